//! A replay's report as a plain-text table.

use super::report::ReplayReport;

/// Seconds to 9 significant decimals without trailing zeros (stamps are ns,
/// so 0.9999999999999998 reads as 1).
fn secs(x: f64) -> String {
    let s = format!("{x:.9}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s.is_empty() || s == "-" {
        "0".into()
    } else {
        s.into()
    }
}

/// A plain-text table of a report at up to `rows` lead times (at least 2).
pub fn table(r: &ReplayReport, rows: usize) -> String {
    let s = &r.summary;
    let mut out = format!(
        "{} replayed on {}-particle {} ({} trajectories, {} starts, {} comparisons, \
         dt {}, horizon {} s, lead grid {} s):\n",
        r.model,
        r.particles,
        if r.system.is_empty() {
            "system"
        } else {
            &r.system
        },
        r.trajectories,
        r.starts,
        r.comparisons,
        secs(r.dt),
        secs(r.horizon),
        secs(r.bin_width)
    );
    if r.start_velocities != "recorded" {
        out += &format!("start velocities: {}\n", r.start_velocities);
    }
    if r.scored_against != "the replayed bag" {
        out += &format!("scored against: {}\n", r.scored_against);
    }
    let still = r.still.as_ref();
    out += &format!(
        "{:>9}  {:>8}  {:>10}  {:>10}  {:>10}  {:>10}{}\n",
        "lead [s]",
        "pairs",
        "RE",
        "EE",
        "ME",
        "ME scaled",
        if still.is_some() { "  RE still" } else { "" }
    );
    let still_at = |i: usize| still.map_or(String::new(), |x| x.cell(i));
    let n = s.t.len();
    for i in crate::metrics::evenly_spaced(n, rows) {
        out += &format!(
            "{:>9.4}  {:>8}  {:>10.3e}  {:>10.3e}  {:>10.3e}  {:>10.3e}{}\n",
            s.t[i],
            r.counts[i],
            s.re.gmean[i],
            s.ee.gmean[i],
            s.me.gmean[i],
            s.me_scaled.gmean[i],
            still_at(i)
        );
    }
    let a = &r.averages;
    out += &format!(
        "{:>9}  {:>8}  {:>10.3e}  {:>10.3e}  {:>10.3e}  {:>10.3e}{}\n",
        "mean",
        "",
        a.re,
        a.ee,
        a.me,
        a.me_scaled,
        still.map_or(String::new(), |x| format!("  {:>8.3e}", x.re_mean))
    );
    if let Some(x) = still {
        out += &x.verdict(a.re);
    }
    if r.diverged > 0 {
        out += &format!(
            "{} of {} rollouts failed before the horizon (counted with errors 1); first: {}\n",
            r.diverged,
            r.starts,
            r.first_failure.as_deref().unwrap_or("")
        );
    }
    out += &format!("energy field: {} ({:?})\n", r.field_source, r.field);
    out
}
