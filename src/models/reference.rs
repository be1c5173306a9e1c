//! What names a model: a trained model file, the reference `still`, or the
//! ground truth `truth:<system>`. Parsed once where a name comes in (command
//! line, node parameter, LoadModel request, Python), typed from there on.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use crate::dynamics::STILL;
use crate::physics::SystemKind;

use super::truth::{TruthError, TRUTH_PREFIX};

/// A model, as named by a user.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ModelRef {
    /// A trained model file (GNODE family or baseline).
    File(PathBuf),
    /// The "nothing moves" reference [`crate::dynamics::Still`].
    Still,
    /// The simulator of a system kind ([`super::truth::truth`]).
    Truth(SystemKind),
}

impl ModelRef {
    /// The reference a path names: `still` and `truth:<system>` are read
    /// as such, anything else (a path that is not UTF-8 too) as a file.
    pub fn from_path(path: &Path) -> Result<ModelRef, TruthError> {
        match path.to_str() {
            Some(s) => s.parse(),
            None => Ok(ModelRef::File(path.to_path_buf())),
        }
    }

    /// The model file, when the reference is one.
    pub fn file(&self) -> Option<&Path> {
        match self {
            ModelRef::File(p) => Some(p),
            ModelRef::Still | ModelRef::Truth(_) => None,
        }
    }
}

impl FromStr for ModelRef {
    type Err = TruthError;

    fn from_str(s: &str) -> Result<ModelRef, TruthError> {
        if s == STILL {
            return Ok(ModelRef::Still);
        }
        match s.strip_prefix(TRUTH_PREFIX) {
            Some(system) => Ok(ModelRef::Truth(system.parse()?)),
            None => Ok(ModelRef::File(s.into())),
        }
    }
}

impl fmt::Display for ModelRef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ModelRef::File(p) => write!(f, "{}", p.display()),
            ModelRef::Still => f.write_str(STILL),
            ModelRef::Truth(kind) => write!(f, "{TRUTH_PREFIX}{kind}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn references_parse_and_print_back() {
        for s in [
            "still",
            "truth:spring",
            "truth:pendulum",
            "bags/models/a.json",
        ] {
            let r: ModelRef = s.parse().unwrap();
            assert_eq!(r.to_string(), s);
        }
        assert_eq!("still".parse::<ModelRef>().unwrap(), ModelRef::Still);
        assert_eq!(
            "truth:pendulum".parse::<ModelRef>().unwrap(),
            ModelRef::Truth(SystemKind::Pendulum)
        );
        let e = "truth:rope".parse::<ModelRef>().unwrap_err().to_string();
        assert!(e.contains("unknown system kind"), "{e}");
        assert_eq!(
            "m.json".parse::<ModelRef>().unwrap().file(),
            Some(Path::new("m.json"))
        );
    }
}
