//! The node's parameters as ROS parameters (ros2-client's parameter
//! services, `ros2 param`): every parameter of the one table declared with
//! its description and range, and run-time changes validated, then applied
//! to the live parameters.

use ros2_client::parameters::{NumericRange, ParameterDescriptor, ParameterType};
use ros2_client::{NodeOptions, ParameterValue};

use super::handles::LiveParams;
use super::params::{runtime_settable, Kind, NodeParams, ParamError, ParamValue, Spec, SPECS};
use super::yaml::Scalar;

/// A ROS parameter value as parameter-file text, for [`NodeParams::set`].
fn scalar(value: &ParameterValue) -> Scalar {
    match value {
        ParameterValue::Boolean(b) => Scalar::Bool(*b),
        ParameterValue::Integer(i) => Scalar::Int(*i),
        ParameterValue::Double(x) => Scalar::Float(*x),
        ParameterValue::String(s) => Scalar::Str(s.clone()),
        ParameterValue::DoubleArray(xs) => {
            Scalar::List(xs.iter().map(|x| Scalar::Float(*x)).collect())
        }
        ParameterValue::IntegerArray(xs) => {
            Scalar::List(xs.iter().map(|i| Scalar::Int(*i)).collect())
        }
        other => Scalar::Str(format!("{other:?}")),
    }
}

/// Checks a run-time change of parameter `name` against `current`: only
/// parameters settable at run time ([`Spec::runtime`]), with the same type and range checks as at
/// start. The refusal says why and what to do instead.
pub fn check_runtime_change(
    current: &NodeParams,
    name: &str,
    value: &ParameterValue,
) -> Result<NodeParams, ParamError> {
    if !runtime_settable(name) {
        return Err(ParamError::NotRuntime(name.to_string()));
    }
    let mut p = current.clone();
    p.set(name, &scalar(value), false)?;
    p.check_together()?;
    Ok(p)
}

/// What `describe_parameters` (`ros2 param describe`) answers for a
/// parameter of the one table: its documentation, whether it can change at
/// run time, and its range.
fn descriptor(
    &Spec {
        name,
        kind,
        doc,
        runtime,
    }: &Spec,
) -> ParameterDescriptor {
    let range = match kind {
        Kind::Int(lo, hi) => NumericRange::IntegerRange {
            from_value: i64::from(lo),
            to_value: i64::from(hi),
            step: 1,
        },
        Kind::Double(_) => NumericRange::FloatingPointRange {
            from_value: 0.0,
            to_value: f64::MAX,
            step: 0.0,
        },
        _ => NumericRange::NotSpecified,
    };
    let constraints = match kind {
        Kind::Topic => "a ROS 2 name: absolute (/a), relative to the namespace (a) or to the \
                        node (~/a)"
            .to_string(),
        Kind::OptTopic => "a ROS 2 name (/a, a or ~/a), or empty = off".to_string(),
        Kind::Double(true) => "finite and > 0".to_string(),
        Kind::Double(false) => "finite and >= 0".to_string(),
        Kind::Doubles(max) => format!("at most {max} finite numbers > 0"),
        Kind::Choice(words) => format!("one of {}", words.join(", ")),
        _ => String::new(),
    };
    ParameterDescriptor {
        name: name.to_string(),
        param_type: ParameterType::NotSet,
        description: doc.to_string(),
        additional_constraints: constraints,
        read_only: !runtime,
        dynamic_typing: false,
        range,
    }
}

/// Every parameter of [`SPECS`] as a ROS parameter, so rclpy can list and
/// get them all; those settable at run time ([`Spec::runtime`]) can be set
/// (validated, then applied to `live`), the others refuse with the reason.
pub(super) fn declare_parameters(p: &NodeParams, live: LiveParams) -> NodeOptions {
    let values: Vec<(&'static str, ParameterValue)> = SPECS
        .iter()
        .filter_map(|s| {
            let v = match p.value(s.name)? {
                ParamValue::Str(x) => ParameterValue::String(x.to_string()),
                ParamValue::Bool(x) => ParameterValue::Boolean(x),
                ParamValue::Int(x) => ParameterValue::Integer(i64::from(x)),
                ParamValue::Double(x) => ParameterValue::Double(x),
                ParamValue::Doubles(xs) => ParameterValue::DoubleArray(xs.to_vec()),
            };
            Some((s.name, v))
        })
        .collect();
    let initial = values.clone();
    let (check, apply) = (live.clone(), live);
    let described = SPECS
        .iter()
        .fold(NodeOptions::new().enable_rosout(true), |o, s| {
            o.describe_parameter(descriptor(s))
        });
    values
        .into_iter()
        .fold(described, |o, (k, v)| o.declare_parameter(k, v))
        // Declaring goes through the validator too: the start values pass.
        .parameter_validator(Box::new(move |name, value| {
            if initial.iter().any(|(k, v)| *k == name && v == value) {
                return Ok(());
            }
            // ros2-client takes the refusal as text.
            check_runtime_change(&check.get(), name, value)
                .map(|_| ())
                .map_err(|e| e.to_string())
        }))
        // Runs after the validator, and for every declared value at start.
        // Other parameters (read-only ones, ros2-client's use_sim_time) need
        // nothing here: the validator refuses changes to the read-only ones.
        .parameter_set_action(Box::new(move |name, value| {
            if !runtime_settable(name) {
                return Ok(());
            }
            apply
                .update(|current| check_runtime_change(current, name, value))
                .map_err(|e| e.to_string())
        }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lead_times_change_at_run_time_from_a_double_array() {
        let p = NodeParams::default();
        let set = |v| check_runtime_change(&p, "accuracy_lead_times", &v);
        let q = set(ParameterValue::DoubleArray(vec![0.1, 1.0])).unwrap();
        assert_eq!(q.accuracy_lead_times, vec![0.1, 1.0]);
        let q = set(ParameterValue::IntegerArray(vec![1, 2])).unwrap();
        assert_eq!(q.accuracy_lead_times, vec![1.0, 2.0]);
        let e = set(ParameterValue::DoubleArray(vec![0.1, 0.0]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("must be finite and > 0"), "{e}");
        let e = set(ParameterValue::Double(0.5)).unwrap_err().to_string();
        assert!(e.contains("must be a list"), "{e}");
    }
}
