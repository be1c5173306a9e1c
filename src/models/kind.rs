//! The kinds of model: the GNODE family and the baselines, one name space.

use crate::baselines::Kind;
use crate::gnode::Variant;

/// A model of the GNODE family or a baseline, named as on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelKind {
    /// NODE, GNODE, CGNODE, CDGNODE, MCGNODE.
    Family(Variant),
    /// LGN, HGN, GNS.
    Baseline(Kind),
}

impl ModelKind {
    /// The lower-case name ("mcgnode", "lgn", ...).
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Family(v) => v.name(),
            ModelKind::Baseline(k) => k.name(),
        }
    }
}

impl crate::names::Named for ModelKind {
    const ALL: &'static [Self] = &[
        ModelKind::Family(Variant::Node),
        ModelKind::Family(Variant::Gnode),
        ModelKind::Family(Variant::Cgnode),
        ModelKind::Family(Variant::Cdgnode),
        ModelKind::Family(Variant::Mcgnode),
        ModelKind::Baseline(Kind::Lgn),
        ModelKind::Baseline(Kind::Hgn),
        ModelKind::Baseline(Kind::Gns),
    ];
    const WHAT: &'static str = "model";

    fn name(self) -> &'static str {
        ModelKind::name(self)
    }
}

crate::impl_named!(ModelKind);
