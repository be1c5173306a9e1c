//! What a bag says about the system it recorded: the simulator configuration
//! of its metadata, the field acting on the particles (and where that was
//! learnt), whether it looks like a closed system, and its stamp interval.
//! Read by training, evaluation and replay alike.

use super::bag::Bag;
use crate::error::{bail, Result};
use crate::physics::{Field, SystemConfig};

/// The simulator configuration a bag was made with, if it says.
pub fn bag_system(bag: &Bag) -> Result<Option<SystemConfig>> {
    Ok(bag.meta()?.system_config)
}

/// Largest drift of total momentum, relative to Σ m|v|, for a recording to
/// count as a closed system (Verlet conserves momentum to rounding).
pub const CLOSED_MOMENTUM_TOL: f64 = 1e-9;
/// Largest drift of the field-free energy (kinetic + springs), relative to its
/// scale, for a recording to count as a closed system: drag that leaves the
/// total momentum at zero still drains energy far beyond this.
pub const CLOSED_ENERGY_TOL: f64 = 1e-3;

/// The field a bag's particles move in, and where that was learnt.
#[derive(Clone, Debug, PartialEq)]
pub struct FieldOrigin {
    /// The field.
    pub field: Field,
    /// Where it came from, in words (shown in reports).
    pub source: String,
}

/// True when every trajectory looks like a closed system: no anchors, total
/// momentum conserved to [`CLOSED_MOMENTUM_TOL`] and the field-free energy to
/// [`CLOSED_ENERGY_TOL`] (relative). Needs at least two samples somewhere.
pub fn looks_closed(bag: &Bag) -> bool {
    let free = Field::default();
    let mut compared = false;
    for tr in &bag.trajectories {
        let g = &tr.graph;
        if !g.anchors.is_empty() {
            return false;
        }
        let Some(first) = tr.samples.first() else {
            continue;
        };
        let p0 = first.state.momentum(g);
        let h0 = crate::physics::hamiltonian(g, &free, &first.state);
        for s in &tr.samples[1..] {
            compared = true;
            let scale: f64 = g
                .masses
                .iter()
                .enumerate()
                .map(|(i, m)| {
                    m * s.state.v[i * g.dim..(i + 1) * g.dim]
                        .iter()
                        .map(|x| x * x)
                        .sum::<f64>()
                        .sqrt()
                })
                .sum::<f64>()
                .max(f64::MIN_POSITIVE);
            let p = s.state.momentum(g);
            let dp = p
                .iter()
                .zip(&p0)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt();
            if dp > CLOSED_MOMENTUM_TOL * scale {
                return false;
            }
            let h = crate::physics::hamiltonian(g, &free, &s.state);
            if (h - h0).abs() > CLOSED_ENERGY_TOL * h0.abs().max(f64::MIN_POSITIVE) {
                return false;
            }
        }
    }
    compared
}

/// The field acting on a bag's particles, from (in order) the flags, the
/// messages' own field entries, or the bag's `system_config` metadata
/// (provenance of older bags); else inferred as a closed system when
/// [`looks_closed`]. `None`: it cannot be known. Messages and metadata that
/// disagree are refused.
pub fn bag_field(bag: &Bag, flag: Option<&Field>) -> Result<Option<FieldOrigin>> {
    let sys = bag_system(bag)?;
    if let (Some(m), Some(s)) = (&bag.field, &sys) {
        if m.normalized() != s.field.normalized() {
            bail!(
                "the messages state the field {m:?} but the bag's system_config says {:?}",
                s.field
            );
        }
    }
    let found = match (flag, &bag.field, &sys) {
        (Some(f), _, _) => Some((f.clone(), "flags".to_string())),
        (None, Some(f), _) => Some((f.clone(), "the messages' field entries".to_string())),
        (None, None, Some(s)) => {
            Some((s.field.normalized(), "the bag's system_config".to_string()))
        }
        (None, None, None) if looks_closed(bag) => Some((
            Field::default(),
            "inferred: a closed system (no anchors; momentum and energy conserved in the data)"
                .to_string(),
        )),
        _ => None,
    };
    Ok(found.map(|(field, source)| FieldOrigin { field, source }))
}

/// The message for a field that cannot be known, naming the flags.
pub fn unknown_field_error(what: &str) -> crate::error::Error {
    crate::error::err!(
        "the bag does not say what acts on the particles (its messages leave the field \
         unknown, it has no system_config metadata, and the data are not those of a closed \
         system), so {what} cannot be computed: pass --gravity G and/or --drag C (the \
         other is then 0), or --closed for no field"
    )
}

/// The interval between recorded states, when it is the same (to 1e-6
/// relative) everywhere: the median over all trajectories, else `None`.
pub fn stamp_interval(bag: &Bag) -> Option<f64> {
    let mut d: Vec<f64> = bag
        .trajectories
        .iter()
        .flat_map(|t| t.samples.windows(2).map(|w| w[1].t - w[0].t))
        .collect();
    if d.is_empty() {
        return None;
    }
    d.sort_by(f64::total_cmp);
    let median = d[d.len() / 2];
    (median > 0.0 && d[d.len() - 1] - d[0] <= 1e-6 * median).then_some(median)
}
