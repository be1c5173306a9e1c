//! The `mcgnode` binary: a thin shell over the library's command line.

fn main() -> std::process::ExitCode {
    match mcgnode::cli::run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", mcgnode::cli::error_report(&e));
            std::process::ExitCode::FAILURE
        }
    }
}
