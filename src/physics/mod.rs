//! Ground-truth physics: one simulator for any [`Graph`] of springs and bars in
//! a field (gravity along −y, linear drag, a constant force).
//!
//! * `forces`: applied forces and the Hamiltonian;
//! * `constraints`: bars, the exact constrained acceleration, residuals;
//! * [`verlet`]: the velocity-Verlet step (drift, kick), written once;
//! * `integrator`: velocity Verlet + SHAKE/RATTLE on the true forces;
//! * `config`: the paper's spring, pendulum and peridynamic-solid systems,
//!   initial states, trajectory generation;
//! * `rk4`: RK4 on (q, p), the paper's HGN training data;
//! * `neighbors`: contact pairs within a radius (cell list) and their edges;
//! * `contact`: the soft-sphere contact force and energy on those pairs;
//! * `drive`: given motion of kinematic particles (grippers, pushers);
//! * `scenes`: the systems that touch (soft spheres in a box, colliding
//!   lattices, a chain falling on a floor), with kinematic walls, and a
//!   chain held by a moving kinematic gripper.
//!
//! The same physics as a model behind [`crate::dynamics::Dynamics`] is
//! [`crate::models::truth::Truth`], above the trait.

pub(crate) mod config;
pub(crate) mod constraints;
pub(crate) mod contact;
pub(crate) mod drive;
mod error;
pub(crate) mod forces;
pub(crate) mod integrator;
pub(crate) mod linalg;
pub(crate) mod neighbors;
pub(crate) mod periodic_cells;
pub(crate) mod projection;
pub(crate) mod rk4;
pub(crate) mod scenes;
mod trajectories;
pub mod verlet;

use serde::{Deserialize, Serialize};

pub use config::{SystemConfig, PERIDYNAMIC_HORIZON};
pub use constraints::{acceleration, bar_jacobian, constraint_residual};
pub use contact::{contact_energy, ContactLaw, Contacts};
pub use drive::{Drive, DriveError};
pub use error::PhysicsError;
pub use forces::{applied_forces, hamiltonian, kinetic_energy, potential_energy};
pub use integrator::Integrator;
pub use neighbors::{
    brute_force_pairs, contact_edge, edges_with_contacts, ContactEdges, NeighborSearch,
};
pub use projection::Projector;
pub use rk4::rk4_trajectories;

#[cfg(doc)]
use crate::system::Graph;

/// The system families of the paper.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SystemKind {
    /// A ring of particles joined by springs.
    Spring,
    /// A chain of particles joined by rigid bars, hanging from the origin.
    Pendulum,
    /// A 3D elastic cube of k×k×k particles, bond-based peridynamics (bonds
    /// are springs to every particle within the horizon
    /// `config::PERIDYNAMIC_HORIZON`), compressed isotropically and released.
    Peridynamic,
    /// Elastic soft spheres in a box whose walls are kinematic particles,
    /// under gravity (`scenes`).
    #[serde(rename = "soft-spheres")]
    SoftSpheres,
    /// Elastic soft spheres in a box periodic on every axis, no walls and no
    /// field: a closed system whose edges cross the box's faces (`scenes`).
    #[serde(rename = "periodic-spheres")]
    PeriodicSpheres,
    /// Two spring lattices thrown at each other, no field: a closed system
    /// whose lattices touch through contacts.
    #[serde(rename = "colliding-lattices")]
    CollidingLattices,
    /// A chain of rigid bars falling onto a floor of kinematic particles.
    #[serde(rename = "falling-chain")]
    FallingChain,
    /// A chain of springs hanging from a kinematic gripper that moves along a
    /// random smooth path, under gravity (`scenes`): action-rich data.
    #[serde(rename = "held-chain")]
    HeldChain,
}

impl SystemKind {
    /// Every kind, in the order they are listed to users.
    pub const ALL: [SystemKind; 8] = [
        SystemKind::Spring,
        SystemKind::Pendulum,
        SystemKind::Peridynamic,
        SystemKind::SoftSpheres,
        SystemKind::PeriodicSpheres,
        SystemKind::CollidingLattices,
        SystemKind::FallingChain,
        SystemKind::HeldChain,
    ];

    /// The spatial dimension [`SystemConfig::new`] gives this kind: 3 for the
    /// peridynamic solid (a cube), 2 otherwise (the paper's setups).
    pub fn default_dim(self) -> usize {
        match self {
            SystemKind::Peridynamic => 3,
            _ => 2,
        }
    }

    /// Whether its particles touch: contact edges within a radius (the
    /// systems of `scenes`).
    pub fn has_contacts(self) -> bool {
        matches!(
            self,
            SystemKind::SoftSpheres
                | SystemKind::PeriodicSpheres
                | SystemKind::CollidingLattices
                | SystemKind::FallingChain
        )
    }

    /// The name used on the command line and in trajectories.
    pub fn name(self) -> &'static str {
        match self {
            SystemKind::Spring => "spring",
            SystemKind::Pendulum => "pendulum",
            SystemKind::Peridynamic => "peridynamic",
            SystemKind::SoftSpheres => "soft-spheres",
            SystemKind::PeriodicSpheres => "periodic-spheres",
            SystemKind::CollidingLattices => "colliding-lattices",
            SystemKind::FallingChain => "falling-chain",
            SystemKind::HeldChain => "held-chain",
        }
    }
}

impl crate::names::Named for SystemKind {
    const ALL: &'static [Self] = &SystemKind::ALL;
    const WHAT: &'static str = "system kind";

    fn name(self) -> &'static str {
        SystemKind::name(self)
    }
}

crate::impl_named!(SystemKind);

/// The field every particle sits in. Missing JSON fields default to 0 / empty.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Field {
    /// Gravitational acceleration g; the force m·g points along −y.
    pub gravity: f64,
    /// Linear drag coefficient c; the force is −c·q̇ (not scaled by mass).
    pub drag: f64,
    /// Constant force on every particle, `dim` entries; empty means zero.
    pub force: Vec<f64>,
}

impl Field {
    /// Checks finiteness, a non-negative drag and the force's length.
    pub fn validate(&self, dim: usize) -> Result<(), PhysicsError> {
        if !self.gravity.is_finite() {
            return Err(PhysicsError::Gravity(self.gravity));
        }
        if !(self.drag.is_finite() && self.drag >= 0.0) {
            return Err(PhysicsError::Drag(self.drag));
        }
        if !self.force.is_empty() && self.force.len() != dim {
            return Err(PhysicsError::ForceLength {
                components: self.force.len(),
                dim,
            });
        }
        if self.force.iter().any(|x| !x.is_finite()) {
            return Err(PhysicsError::ForceNotFinite);
        }
        Ok(())
    }

    /// The same field with an all-zero `force` written as empty, so that two
    /// descriptions of one field compare equal.
    pub fn normalized(&self) -> Field {
        Field {
            gravity: self.gravity,
            drag: self.drag,
            force: if self.force.iter().all(|x| *x == 0.0) {
                vec![]
            } else {
                self.force.clone()
            },
        }
    }

    /// True when nothing but internal forces act: no gravity, drag or force,
    /// so total momentum is conserved (for graphs without anchors).
    pub fn is_free(&self) -> bool {
        self.gravity == 0.0 && self.drag == 0.0 && self.force.iter().all(|x| *x == 0.0)
    }
}
