//! The machine's core count, asked once.

/// The number of cores, for `--threads` defaults and per-call choices.
/// Asked once: on Linux the question reads the cgroup's CPU quota files,
/// which costs more than a small model's whole rollout.
pub fn all_cores() -> usize {
    static CORES: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    *CORES.get_or_init(|| std::thread::available_parallelism().map_or(1, std::num::NonZero::get))
}
