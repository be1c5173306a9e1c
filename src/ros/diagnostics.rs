//! What the node reports about itself: `NodeDiagnostics` and the standard
//! `/diagnostics` (with live accuracy) every `diagnostics_period`, what it
//! serves at start, and what it recorded at shutdown.

use std::sync::atomic::Ordering;
use std::time::Duration;

use ros2_client::log::LogLevel;
use ros2_client::Publisher;

use super::accuracy::{self, Level};
use super::handles::Handles;
use super::params::NODE_NAME;
use super::resource_names::Names;
use super::topics::LIVE_ACCURACY_TOPIC;
use super::wire::{
    DiagnosticArray, DiagnosticStatus, KeyValue, NodeDiagnostics, DIAGNOSTIC_OK, DIAGNOSTIC_WARN,
};

/// The counters now, stamped with the node's clock.
fn node_diagnostics(h: &Handles) -> NodeDiagnostics {
    NodeDiagnostics {
        header: h.clock.header(),
        ..h.diag.snapshot(&h.model.get().describe())
    }
}

/// The counters as a standard `DiagnosticArray` with one status, `mcgnode:
/// predictions`: WARN when states were rejected or dropped since the previous
/// report (`before`), OK otherwise.
pub fn standard_diagnostics(
    d: &NodeDiagnostics,
    dropped: u64,
    before: (u64, u64),
) -> DiagnosticArray {
    let (rejected_now, dropped_now) = (
        d.rejected.saturating_sub(before.0),
        dropped.saturating_sub(before.1),
    );
    let (level, message) = if rejected_now > 0 || dropped_now > 0 {
        (
            DIAGNOSTIC_WARN,
            format!(
                "{rejected_now} states rejected, {dropped_now} dropped since the last report; \
                 last error: {}",
                d.last_error
            ),
        )
    } else {
        (DIAGNOSTIC_OK, format!("serving {}", d.model))
    };
    let kv = |key: &str, value: String| KeyValue {
        key: key.into(),
        value,
    };
    DiagnosticArray {
        header: d.header.clone(),
        status: vec![DiagnosticStatus {
            level,
            name: format!("{NODE_NAME}: predictions"),
            message,
            hardware_id: NODE_NAME.into(),
            values: vec![
                kv("received", d.received.to_string()),
                kv("rejected", d.rejected.to_string()),
                kv("predicted", d.predicted.to_string()),
                kv("out_of_range", d.out_of_range.to_string()),
                kv("derived", d.derived.to_string()),
                kv("warming_up", d.warming_up.to_string()),
                kv("history_resets", d.history_resets.to_string()),
                kv("dropped", dropped.to_string()),
                kv("last_error", d.last_error.clone()),
                kv("model", d.model.clone()),
            ],
        }],
    }
}

/// The model smoother's cost per state over its last fits (up to 1,000):
/// `smoother_cost_median_ms`, `smoother_cost_p99_ms`, `smoother_fits`;
/// nothing before its first fit.
pub fn smoother_cost_values(cost: Option<super::smoother::CostSummary>) -> Vec<KeyValue> {
    cost.map_or_else(Vec::new, |c| {
        vec![
            KeyValue {
                key: "smoother_cost_median_ms".into(),
                value: format!("{:.4}", c.median_ms),
            },
            KeyValue {
                key: "smoother_cost_p99_ms".into(),
                value: format!("{:.4}", c.p99_ms),
            },
            KeyValue {
                key: "smoother_fits".into(),
                value: c.fits.to_string(),
            },
        ]
    })
}

/// An ensemble's spread: `spread_max`, the largest particle spread along
/// the latest prediction's horizon (positions' units); nothing for a single
/// model.
pub fn spread_values(spread_max: Option<f64>) -> Vec<KeyValue> {
    spread_max.map_or_else(Vec::new, |m| {
        vec![KeyValue {
            key: "spread_max".into(),
            value: format!("{m:.6e}"),
        }]
    })
}

/// An ensemble's spread alarm as a standard diagnostic status, `mcgnode:
/// spread`: WARN when the latest prediction's largest particle spread
/// passes `warn` (0 = never); nothing for a single model.
pub fn spread_status(spread_max: Option<f64>, warn: f64) -> Option<DiagnosticStatus> {
    let max = spread_max?;
    let (level, message) = if warn > 0.0 && (max > warn || max.is_nan()) {
        (
            Level::Warn,
            format!("the ensemble disagrees: largest spread {max:.3e}, above spread_warn = {warn}"),
        )
    } else {
        (Level::Ok, format!("largest spread {max:.3e}"))
    };
    Some(DiagnosticStatus {
        level: level as u8,
        name: format!("{NODE_NAME}: spread"),
        message,
        hardware_id: NODE_NAME.into(),
        values: spread_values(Some(max)),
    })
}

/// Live accuracy as a standard diagnostic status, `mcgnode: live accuracy`:
/// the drift alarm's level and message, and per lead time the running and
/// latest RE and EE and the number of comparisons (`re_mean@0.5s`, ...).
pub fn accuracy_status(
    figures: &[accuracy::LeadAccuracy],
    level: Level,
    why: &str,
    overflowed: u64,
) -> DiagnosticStatus {
    let kv = |key: String, value: String| KeyValue { key, value };
    let mut values = Vec::with_capacity(5 * figures.len() + 1);
    for f in figures {
        let at = |what: &str| format!("{what}@{}s", f.lead);
        values.push(kv(at("compared"), f.compared.to_string()));
        values.push(kv(at("re_mean"), format!("{:.6e}", f.re_mean)));
        values.push(kv(at("re"), format!("{:.6e}", f.re)));
        values.push(kv(at("ee_mean"), format!("{:.6e}", f.ee_mean)));
        values.push(kv(at("ee"), format!("{:.6e}", f.ee)));
    }
    values.push(kv("pending_dropped".into(), overflowed.to_string()));
    DiagnosticStatus {
        level: level as u8,
        name: format!("{NODE_NAME}: live accuracy"),
        message: why.to_string(),
        hardware_id: NODE_NAME.into(),
        values,
    }
}

/// Publishes `NodeDiagnostics` and the standard `/diagnostics` every
/// `diagnostics_period`.
pub(super) async fn diagnostics_loop(
    h: Handles,
    publisher: Publisher<NodeDiagnostics>,
    standard: Publisher<DiagnosticArray>,
) {
    let period = h.params.get().diagnostics_period;
    let mut tick = tokio::time::interval(Duration::from_secs_f64(period));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut before = (0, 0);
    loop {
        tick.tick().await;
        let d = node_diagnostics(&h);
        let dropped = h.diag.stats.dropped.load(Ordering::Relaxed);
        let mut array = standard_diagnostics(&d, dropped, before);
        array.status[0]
            .values
            .extend(smoother_cost_values(h.inputs.smoother_cost()));
        array.status[0]
            .values
            .extend(spread_values(h.diag.stats.spread_max()));
        let spread = h.diag.stats.spread_max();
        array
            .status
            .extend(spread_status(spread, h.params.get().spread_warn));
        if let Some((figures, level, why, overflowed)) = h.accuracy.figures(&h.params.get()) {
            array
                .status
                .push(accuracy_status(&figures, level, &why, overflowed));
        }
        before = (d.rejected, dropped);
        if let Err(e) = publisher.async_publish(d).await {
            eprintln!("[WARN] [{NODE_NAME}]: publishing diagnostics failed: {e:?}");
        }
        if let Err(e) = standard.async_publish(array).await {
            eprintln!("[WARN] [{NODE_NAME}]: publishing /diagnostics failed: {e:?}");
        }
    }
}

/// Says what the node serves, where.
pub(super) fn log_start(h: &Handles, names: &Names, domain_id: u16) {
    let p = h.params.get();
    h.diag.log(
        LogLevel::Info,
        &format!(
            "serving {} in domain {domain_id}: {} -> {} + {} (horizon {}, dt {}), service {}",
            h.model.get().describe(),
            p.input_topic,
            p.trajectory_topic,
            p.forces_topic,
            p.horizon,
            p.dt,
            p.rollout_service
        ),
    );
    if p.lifecycle {
        h.diag.log(
            LogLevel::Info,
            &format!(
                "managed lifecycle: unconfigured, predicting nothing until configure and \
                 activate ({}/change_state)",
                names.fqn()
            ),
        );
    }
    if !p.accuracy_lead_times.is_empty() {
        let t = accuracy::Tracker::new(&p.accuracy_lead_times, 1, 1);
        let reachable: Vec<f64> = t
            .steps(p.timing())
            .iter()
            .map(|(i, _)| p.accuracy_lead_times[*i])
            .collect();
        let level = if reachable.len() == p.accuracy_lead_times.len() {
            LogLevel::Info
        } else {
            LogLevel::Warn
        };
        // A lead the prediction does not reach, or not a whole number of
        // steps, is never compared: say so once rather than stay silent.
        h.diag.log(
            level,
            &format!(
                "live accuracy on {LIVE_ACCURACY_TOPIC} at lead times {:?} s; comparable with \
                 horizon {} x dt {}: {reachable:?}",
                p.accuracy_lead_times, p.horizon, p.dt
            ),
        );
    }
}

/// Closes the open bag at shutdown and says what was recorded.
pub(super) fn finish_recording(h: &Handles) {
    match h.recorder.close() {
        None => {}
        Some(Ok((dir, finished))) => h.diag.log(
            LogLevel::Info,
            &format!("recorded {} bag(s) in {}", finished.len(), dir.display()),
        ),
        Some(Err(e)) => h.diag.log(LogLevel::Error, &e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_spread_alarm_warns_above_its_threshold_only() {
        assert!(
            spread_status(None, 1e-3).is_none(),
            "a single model has none"
        );
        let ok = spread_status(Some(5e-4), 1e-3).unwrap();
        assert_eq!(ok.level, Level::Ok as u8);
        assert_eq!(ok.values[0].key, "spread_max");
        let warn = spread_status(Some(2e-3), 1e-3).unwrap();
        assert_eq!(warn.level, Level::Warn as u8);
        assert!(warn.message.contains("spread_warn"), "{}", warn.message);
        assert_eq!(
            spread_status(Some(2e-3), 0.0).unwrap().level,
            Level::Ok as u8
        );
        let nan = spread_status(Some(f64::NAN), 1e-3).unwrap();
        assert_eq!(nan.level, Level::Warn as u8, "a NaN spread is not trusted");
    }

    #[test]
    fn standard_diagnostics_warn_on_new_rejections_only() {
        let d = NodeDiagnostics {
            received: 10,
            rejected: 3,
            predicted: 7,
            last_error: "state too large".into(),
            model: "truth:spring".into(),
            ..NodeDiagnostics::default()
        };
        let a = standard_diagnostics(&d, 2, (1, 2));
        let s = &a.status[0];
        assert_eq!(s.level, DIAGNOSTIC_WARN);
        assert!(
            s.message.contains("2 states rejected, 0 dropped"),
            "{}",
            s.message
        );
        assert!(s.message.contains("state too large"), "{}", s.message);
        let value = |k: &str| {
            s.values
                .iter()
                .find(|v| v.key == k)
                .map(|v| v.value.clone())
        };
        assert_eq!(value("dropped").as_deref(), Some("2"));
        assert_eq!(value("predicted").as_deref(), Some("7"));
        let quiet = standard_diagnostics(&d, 2, (3, 2));
        assert_eq!(quiet.status[0].level, DIAGNOSTIC_OK);
    }

    #[test]
    fn accuracy_status_carries_level_lead_and_values() {
        let f = accuracy::LeadAccuracy {
            lead: 0.5,
            compared: 4,
            re: 0.03,
            re_mean: 0.02,
            ee: f64::NAN,
            ee_mean: f64::NAN,
        };
        let (level, why) = accuracy::alarm(std::slice::from_ref(&f), 0.01, 0.1);
        let s = accuracy_status(&[f], level, &why, 0);
        assert_eq!(s.level, crate::ros::wire::DIAGNOSTIC_WARN);
        assert!(s.message.contains("lead 0.5 s"), "{}", s.message);
        let get = |k: &str| s.values.iter().find(|v| v.key == k).map(|v| &v.value);
        assert_eq!(get("compared@0.5s").map(String::as_str), Some("4"));
        assert_eq!(get("re_mean@0.5s").map(String::as_str), Some("2.000000e-2"));
        assert_eq!(get("ee_mean@0.5s").map(String::as_str), Some("NaN"));
    }
}
