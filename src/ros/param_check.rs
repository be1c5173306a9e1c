//! Checking one parameter value against its [`Kind`] (name, type, range)
//! before it is stored, and what single parameters cannot check alone.

use super::params::{spec, Kind, NodeParams, ParamError, Slot};
use super::resource_names::is_ros_name;
use super::yaml::Scalar;

impl NodeParams {
    /// Sets one parameter, checking its name, type and range. Command-line
    /// values for string parameters are taken as text whatever they look like.
    pub fn set(&mut self, key: &str, value: &Scalar, from_cli: bool) -> Result<(), ParamError> {
        let Some(kind) = spec(key).map(|s| s.kind) else {
            return Err(ParamError::Unknown(key.to_string()));
        };
        let given = Given { key, value };
        let checked = match kind {
            Kind::Str | Kind::Topic | Kind::OptTopic => Put::Str(given.text(kind, from_cli)?),
            Kind::Choice(words) => Put::Str(given.choice(words)?),
            Kind::Bool => Put::Bool(given.flag()?),
            Kind::Int(lo, hi) => Put::Int(given.int(lo, hi)?),
            Kind::Double(positive) => Put::Double(given.double(positive)?),
            Kind::Doubles(max) => Put::Doubles(given.doubles(max)?),
        };
        self.put(key, checked);
        Ok(())
    }

    /// Stores a checked value through its typed slot; the kind in [`SPECS`]
    /// and the field's type agree (tested over the whole table).
    fn put(&mut self, key: &str, value: Put) {
        match (self.slot(key), value) {
            (Some(Slot::Str(x)), Put::Str(v)) => *x = v,
            (Some(Slot::Bool(x)), Put::Bool(v)) => *x = v,
            (Some(Slot::Int(x)), Put::Int(v)) => *x = v,
            (Some(Slot::Double(x)), Put::Double(v)) => *x = v,
            (Some(Slot::Doubles(x)), Put::Doubles(v)) => *x = v,
            _ => unreachable_key(key),
        }
    }

    /// Checks what single parameters cannot: a poly smoother's window holds
    /// at least `smoother_order + 2` states, and tracker topics have a
    /// template.
    pub fn check_together(&self) -> Result<(), ParamError> {
        let tracker = !self.pose_array_topic.is_empty() || !self.point_cloud_topic.is_empty();
        if tracker && self.input_template.is_empty() {
            return Err(ParamError::Together(
                "pose_array_topic, point_cloud_topic: need input_template, a bag or a .yaml \
                 file of ParticleState fields giving the particles' types, masses and graph"
                    .into(),
            ));
        }
        crate::data::stream::Smoother::new(
            &self.velocity_smoother,
            self.smoother_window as usize,
            self.smoother_order as usize,
        )
        .map(|_| ())
        .map_err(|e| ParamError::Together(format!("smoother_window, smoother_order: {e}")))
    }
}

/// A checked value on its way into its field.
enum Put {
    Str(String),
    Bool(bool),
    Int(u32),
    Double(f64),
    Doubles(Vec<f64>),
}

/// A value given for parameter `key`, checked against the parameter's kind.
struct Given<'a> {
    key: &'a str,
    value: &'a Scalar,
}

impl Given<'_> {
    /// The value is not of the type `want` says.
    fn ill(&self, want: &str) -> ParamError {
        ParamError::IllTyped {
            key: self.key.to_string(),
            want: want.to_string(),
            got: format!("{} {}", self.value.type_name(), self.value),
        }
    }

    /// Text ([`Kind::Str`]) or a ROS 2 name ([`Kind::Topic`]; [`Kind::OptTopic`]
    /// also empty).
    fn text(&self, kind: Kind, from_cli: bool) -> Result<String, ParamError> {
        let value = self.value;
        let s = match value {
            Scalar::Str(s) => s.clone(),
            Scalar::Null if kind != Kind::Topic => String::new(),
            Scalar::Bool(_) | Scalar::Int(_) | Scalar::Float(_) if from_cli => value.to_string(),
            _ => return Err(self.ill("a string")),
        };
        let off = kind == Kind::OptTopic && s.is_empty();
        if matches!(kind, Kind::Topic | Kind::OptTopic) && !off && !is_ros_name(&s) {
            return Err(ParamError::BadName {
                key: self.key.to_string(),
                name: s,
            });
        }
        Ok(s)
    }

    /// One of `words`.
    fn choice(&self, words: &[&str]) -> Result<String, ParamError> {
        let Scalar::Str(w) = self.value else {
            return Err(self.ill(&format!("one of {}", words.join(", "))));
        };
        if !words.contains(&w.as_str()) {
            return Err(self.ill(&format!("one of {}", words.join(", "))));
        }
        Ok(w.clone())
    }

    /// `true` or `false`.
    fn flag(&self) -> Result<bool, ParamError> {
        match self.value {
            Scalar::Bool(b) => Ok(*b),
            _ => Err(self.ill("true or false")),
        }
    }

    /// An integer in `lo..=hi`.
    fn int(&self, lo: u32, hi: u32) -> Result<u32, ParamError> {
        let Scalar::Int(i) = self.value else {
            return Err(self.ill(&format!("an integer in {lo}..={hi}")));
        };
        u32::try_from(*i)
            .ok()
            .filter(|v| (lo..=hi).contains(v))
            .ok_or_else(|| ParamError::OutOfRange {
                key: self.key.to_string(),
                value: *i,
                lo,
                hi,
            })
    }

    /// A finite number, > 0 when `positive`, else >= 0.
    fn double(&self, positive: bool) -> Result<f64, ParamError> {
        let Some(x) = number(self.value) else {
            return Err(self.ill("a number"));
        };
        let ok = x.is_finite() && if positive { x > 0.0 } else { x >= 0.0 };
        if !ok {
            let want = if positive { "> 0" } else { ">= 0" };
            return Err(ParamError::NotPositive {
                key: self.key.to_string(),
                value: x,
                want,
            });
        }
        Ok(x)
    }

    /// A list of at most `max` finite numbers > 0.
    fn doubles(&self, max: usize) -> Result<Vec<f64>, ParamError> {
        let Scalar::List(items) = self.value else {
            return Err(self.ill(&format!("a list of at most {max} numbers > 0")));
        };
        if items.len() > max {
            return Err(ParamError::TooLong {
                key: self.key.to_string(),
                len: items.len(),
                max,
            });
        }
        let mut xs = Vec::with_capacity(items.len());
        for item in items {
            let Some(x) = number(item) else {
                return Err(self.ill(&format!("a list of at most {max} numbers > 0")));
            };
            if !(x.is_finite() && x > 0.0) {
                return Err(ParamError::BadEntry {
                    key: self.key.to_string(),
                    value: x,
                });
            }
            xs.push(x);
        }
        Ok(xs)
    }
}

/// A YAML number as a double (integers too).
fn number(value: &Scalar) -> Option<f64> {
    match value {
        Scalar::Float(x) => Some(*x),
        Scalar::Int(i) => Some(*i as f64),
        _ => None,
    }
}

/// A kind in SPECS that does not fit its field's type is a bug caught by the
/// tests, and must not panic a running node.
fn unreachable_key(key: &str) {
    debug_assert!(false, "parameter {key}: its kind does not fit its field");
}

#[cfg(test)]
mod tests {
    use super::super::params::{Spec, SPECS};
    use super::*;

    /// Setting one bool changes that parameter and no other.
    #[test]
    fn each_bool_sets_only_itself() {
        let d = NodeParams::default();
        for Spec {
            name: key, kind, ..
        } in SPECS
        {
            if *kind != Kind::Bool {
                continue;
            }
            let flipped = d.raw_value(key) != "true";
            let mut p = d.clone();
            p.set(key, &Scalar::Bool(flipped), false).unwrap();
            assert_eq!(p.raw_value(key), flipped.to_string(), "{key}");
            for other in SPECS.iter().map(|s| s.name).filter(|k| k != key) {
                assert_eq!(
                    p.raw_value(other),
                    d.raw_value(other),
                    "{key} changed {other}"
                );
            }
        }
    }
}
