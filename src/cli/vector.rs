//! Vectors on the command line (`--force 0,-1`).

/// A vector given as one argument, "x,y,z" (a newtype, so that clap takes
/// it as one value rather than a list of numbers).
#[derive(Clone, Debug, PartialEq)]
pub struct Vector(pub Vec<f64>);

/// Parses "x,y[,z]".
pub(crate) fn parse_vector(s: &str) -> anyhow::Result<Vector> {
    s.split(',')
        .map(|x| match x.trim().parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => Err(anyhow::anyhow!("not finite")),
            Err(_) => Err(anyhow::anyhow!("{x:?} is not a number")),
        })
        .collect::<anyhow::Result<Vec<f64>>>()
        .map(Vector)
}
