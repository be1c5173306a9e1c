//! What can be wrong with the input of the ground-truth physics.

use super::SystemKind;
use crate::system::SystemError;

/// Invalid input to the physics: a field, a system configuration, an
/// integrator's start, or a simulation that diverged.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PhysicsError {
    /// The graph or a state is invalid.
    #[error(transparent)]
    System(#[from] SystemError),
    /// Gravity is not finite.
    #[error("gravity {0} is not finite")]
    Gravity(f64),
    /// Drag is negative or not finite.
    #[error("drag {0} must be a finite number ≥ 0")]
    Drag(f64),
    /// The external force has the wrong number of components.
    #[error("external force has {components} components, the system is {dim}-dimensional")]
    ForceLength {
        /// Components given.
        components: usize,
        /// The system's dimension.
        dim: usize,
    },
    /// The external force is not finite.
    #[error("external force is not finite")]
    ForceNotFinite,
    /// A peridynamic solid's particle count is not a cube.
    #[error("a peridynamic solid needs a cube number of particles (8, 27, 64, 125, ...), got {0}")]
    NotACube(usize),
    /// A peridynamic solid asked for in 2D.
    #[error("a peridynamic solid is 3-dimensional: dimension must be 3, got {0}")]
    SolidDimension(usize),
    /// Fewer particles than the system needs.
    #[error("a {kind} system needs at least {min} particles, got {got}")]
    TooFewParticles {
        /// The system.
        kind: SystemKind,
        /// Its minimum.
        min: usize,
        /// Particles asked for.
        got: usize,
    },
    /// A parameter that must be positive and finite is not.
    #[error("{name} must be a positive finite number, got {value}")]
    NotPositive {
        /// The parameter.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// A count that must be at least 1 is 0.
    #[error("{0} must be at least 1")]
    AtLeastOne(&'static str),
    /// More trajectories than ids.
    #[error("too many trajectories: {0}")]
    TooManyTrajectories(usize),
    /// A simulated trajectory turned non-finite.
    #[error("trajectory {id} diverged (non-finite state) at sample {sample}; try a smaller dt")]
    Diverged {
        /// The trajectory.
        id: u32,
        /// The first non-finite sample.
        sample: usize,
    },
    /// An RK4 trajectory ([`super::rk4`]) turned invalid.
    #[error("trajectory {id} diverged at sample {sample}: {cause}")]
    Rk4Diverged {
        /// The trajectory.
        id: usize,
        /// The first invalid sample.
        sample: usize,
        /// What is invalid.
        cause: SystemError,
    },
    /// A simulation worker thread panicked.
    #[error("trajectory {0}: worker thread panicked")]
    WorkerPanicked(usize),
    /// The integration step is not positive and finite.
    #[error("time step must be a positive finite number, got {0}")]
    TimeStep(f64),
    /// A bar of length zero or less.
    #[error("bar from particle {0} has non-positive length")]
    BarLength(usize),
}

crate::error::typed_errors!(PhysicsError);
