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
    /// Colliding lattices need two equal square/cubic lattices.
    #[error("colliding lattices need 2·k^dim particles (two {dim}D lattices of side k ≥ 2: 2D 8, 18, 32, 50, ...; 3D 16, 54, 128, ...), got {particles}")]
    NotTwoLattices {
        /// Particles asked for.
        particles: usize,
        /// The dimension.
        dim: usize,
    },
    /// A contact parameter out of range.
    #[error("{name} = {value} is invalid for a {kind} system: it must be finite, positive for the systems that touch, ≥ 0 otherwise")]
    ContactParameter {
        /// The parameter.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The system.
        kind: SystemKind,
    },
    /// The ground-truth model asked for a graph with contacts.
    #[error("the graph has contacts (interaction radius {0}) but the truth:<system> model knows no contact law yet; simulate with `mcgnode simulate` instead")]
    NoContactLaw(f64),
    /// RK4 data asked for a system with contacts or kinematic particles.
    #[error(
        "RK4 data covers springs and bars only: a {0} system touches; use --integrator verlet"
    )]
    Rk4Contacts(SystemKind),
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
    /// An RK4 trajectory (`super::rk4`) turned invalid.
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
    /// A kinematic particle starts moving (the simulator holds them still).
    #[error("kinematic particle {0} has a non-zero velocity: the simulator holds kinematic particles still, start them at rest")]
    KinematicMoving(usize),
    /// A rigid bar ends at a kinematic particle.
    #[error("a bar from particle {0} ends at a kinematic particle: bars must join free particles (or an anchor)")]
    KinematicBar(usize),
    /// The contact stiffness is negative or not finite.
    #[error("contact stiffness {0} must be a finite number ≥ 0")]
    ContactStiffness(f64),
    /// The kinematic particles' given motion does not fit the system.
    #[error("{0}")]
    Drive(String),
}

crate::error::typed_errors!(PhysicsError);
