//! The library's choice enums as clap value enums: clap stays in src/cli.
//! Each mirror keeps the variant docs that `--help` lists as the possible
//! values, and turns into the library's enum with `From`.

use crate::gnode::{ArchPreset, EdgeInput, MessageFn};
use crate::plan::CostKind;
use crate::simulate::DataIntegrator;
use crate::train::{BodyForce, EngineKind, Recipe};

/// A clap value enum `$arg` mirroring the library's `$lib`, variant for
/// variant, with `From` both ways (clap's defaults read the library's).
macro_rules! value_enum {
    ($(#[$m:meta])* $arg:ident => $lib:ident { $($(#[$vm:meta])* $v:ident),* $(,)? }) => {
        $(#[$m])*
        #[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
        pub enum $arg {
            $($(#[$vm])* $v),*
        }

        impl From<$arg> for $lib {
            fn from(a: $arg) -> $lib {
                match a {
                    $($arg::$v => $lib::$v),*
                }
            }
        }

        // The other way: clap's defaults read the library's.
        impl From<$lib> for $arg {
            fn from(a: $lib) -> $arg {
                match a {
                    $($lib::$v => $arg::$v),*
                }
            }
        }
    };
}

value_enum! {
    /// `--recipe`.
    RecipeArg => Recipe {
        /// Chosen from the data (the default).
        Auto,
        /// The paper's appendix.
        Paper,
    }
}

value_enum! {
    /// `--arch`.
    ArchArg => ArchPreset {
        /// What the authors' code ran, behind the paper's numbers: two hidden
        /// layers per MLP, MLP message functions, h_i ⊙ h_j in the edge update.
        Authors,
        /// The paper's text: one hidden layer, linear message functions, h_i ‖ h_j.
        Paper,
    }
}

value_enum! {
    /// `--messages`.
    MessageFnArg => MessageFn {
        /// One linear map (the paper's equations).
        Linear,
        /// An MLP with the graph MLPs' hidden layers (the authors' code).
        Mlp,
    }
}

value_enum! {
    /// `--edge-update`.
    EdgeInputArg => EdgeInput {
        /// h_i ‖ h_j (the paper's equation).
        Concat,
        /// h_i ⊙ h_j (the authors' code).
        Product,
    }
}

value_enum! {
    /// `--body-force`.
    BodyForceArg => BodyForce {
        /// On unless the bag says the system is closed (no field, no anchors).
        Auto,
        /// Always learn body forces.
        On,
        /// Never: internal forces only, momentum conserved exactly.
        Off,
    }
}

value_enum! {
    /// `--engine`.
    EngineArg => EngineKind {
        /// Hand-written reverse mode on the kernel's layout, over all cores (default).
        Native,
        /// Candle's autodiff: the reference.
        Candle,
    }
}

value_enum! {
    /// `plan --cost`.
    CostArg => CostKind {
        /// Distance to the targets at the end of the horizon.
        Final,
        /// Mean distance over the horizon's control steps: get there soon and stay.
        Along,
    }
}

value_enum! {
    /// `simulate --integrator`.
    IntegratorArg => DataIntegrator {
        /// Velocity Verlet (+ SHAKE/RATTLE for bars): symplectic, bars exact.
        Verlet,
        /// Classical RK4 on (q, p) with the exact constrained acceleration
        /// ([`crate::physics::rk4::rk4_trajectories`]): the paper's HGN data.
        Rk4,
    }
}

/// `plan --sampler`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum SamplerArg {
    /// One round of random sequences around the warm start.
    Random,
    /// Cross-entropy method: rounds refitted to the elites.
    Cem,
    /// Model-predictive path integral: rounds averaged with weights exp(−cost/λ).
    Mppi,
}
