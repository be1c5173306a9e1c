//! The kinds of model: the GNODE family and the baselines, one name space.

/// A model of the GNODE family or a baseline, named as on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelKind {
    /// NODE, GNODE, CGNODE, CDGNODE, MCGNODE.
    Family(crate::model::Variant),
    /// LGN, HGN, GNS.
    Baseline(crate::baselines::Kind),
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

impl std::fmt::Display for ModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for ModelKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s.parse::<crate::model::Variant>() {
            Ok(v) => Ok(ModelKind::Family(v)),
            Err(_) => s
                .parse::<crate::baselines::Kind>()
                .map(ModelKind::Baseline)
                .map_err(|_| {
                    format!(
                        "unknown model {s:?}; expected one of node, gnode, cgnode, cdgnode, \
                     mcgnode, lgn, hgn, gns"
                    )
                }),
        }
    }
}
