//! How big each experiment of `mcgnode reproduce` is: the full run and the
//! `--quick` run differ only here.

use serde::Serialize;

/// Sizes, epochs and horizons of every experiment.
#[derive(Clone, Debug, Serialize)]
pub struct Scale {
    /// Name shown in the report ("full" or "quick").
    pub name: String,
    /// Epochs of MCGNODE, LGN, HGN and GNS in the baseline comparison (paper: 10,000).
    pub epochs: usize,
    /// Epochs of the GNODE family in the bias comparison, the large rings and
    /// the drag/force experiment (paper: 10,000).
    pub family_epochs: usize,
    /// Training trajectories of the 5-spring and 5-pendulum (100 states each; paper: 100).
    pub train_trajectories: usize,
    /// Test trajectories per size for the GNODE family (paper: 100).
    pub test_trajectories: usize,
    /// Test trajectories per size for LGN, HGN and GNS (their candle rollouts
    /// cost milliseconds per step, the kernel microseconds).
    pub baseline_test_trajectories: usize,
    /// Saved spring test states, 0.1 s apart (201: the paper's 20 s).
    pub spring_states: usize,
    /// Saved pendulum test states, 0.01 s apart (101: the paper's 1 s).
    pub pendulum_states: usize,
    /// Rollout step of every model on the pendulum (the truth uses 1e-5).
    pub pendulum_dt: f64,
    /// Spring sizes the GNODE family is evaluated on (trained on 5).
    pub spring_sizes: Vec<usize>,
    /// Pendulum sizes the GNODE family is evaluated on (trained on 5).
    pub pendulum_sizes: Vec<usize>,
    /// Spring sizes LGN, HGN and GNS are evaluated on.
    pub baseline_spring_sizes: Vec<usize>,
    /// Pendulum sizes LGN, HGN and GNS are evaluated on.
    pub baseline_pendulum_sizes: Vec<usize>,
    /// Large spring rings for MCGNODE and GNODE: (particles, trajectories).
    pub large_springs: Vec<(usize, usize)>,
    /// Particles of the peridynamic cube (a cube number; paper: 125).
    pub peri_particles: usize,
    /// Peridynamic training trajectories (100 states, 0.1 s apart).
    pub peri_train_trajectories: usize,
    /// Peridynamic test trajectories.
    pub peri_test_trajectories: usize,
    /// Saved peridynamic test states (100: the paper's 9.9 s).
    pub peri_states: usize,
    /// Epochs of the peridynamic models.
    pub peri_epochs: usize,
    /// Free particles of the contact experiment's soft-sphere box (its
    /// zero-shot test has 4x as many).
    pub contact_balls: usize,
    /// Training and test trajectories of the contact experiment (31 states,
    /// 0.1 s apart).
    pub contact_train_trajectories: usize,
    /// See [`Scale::contact_train_trajectories`].
    pub contact_test_trajectories: usize,
    /// Epochs of MCGNODE, GNODE and GNS (equal epochs) on contacts.
    pub contact_epochs: usize,
    /// Epochs of the drag/force, noise and data-efficiency models.
    pub sweep_epochs: usize,
    /// Training trajectories of the drag/force and noise experiments.
    pub sweep_train_trajectories: usize,
    /// Test trajectories of the drag/force, noise and data-efficiency experiments.
    pub sweep_test_trajectories: usize,
    /// Saved test states of those experiments, 0.1 s apart.
    pub sweep_states: usize,
    /// Noise levels, % of the std of the accelerations (paper: 0, 1, 5, 10).
    pub noise: Vec<f64>,
    /// Training-set sizes in states (paper: 100 … 10,000).
    pub points: Vec<usize>,
}

impl Scale {
    /// The full run: the paper's protocol with fewer epochs and test
    /// trajectories, sized to finish in well under an hour on 2 cores.
    pub fn full() -> Self {
        Scale {
            name: "full".into(),
            epochs: 200,
            family_epochs: 2000,
            train_trajectories: 50,
            test_trajectories: 20,
            baseline_test_trajectories: 4,
            spring_states: 201,
            pendulum_states: 101,
            pendulum_dt: 1e-4,
            spring_sizes: vec![3, 4, 5, 20, 50],
            pendulum_sizes: vec![3, 4, 5, 10, 20],
            baseline_spring_sizes: vec![5, 20, 50],
            baseline_pendulum_sizes: vec![3, 5, 10],
            large_springs: vec![(500, 4), (5000, 2)],
            peri_particles: 125,
            peri_train_trajectories: 10,
            peri_test_trajectories: 4,
            peri_states: 100,
            peri_epochs: 300,
            contact_balls: 100,
            contact_train_trajectories: 20,
            contact_test_trajectories: 4,
            contact_epochs: 1000,
            sweep_epochs: 200,
            sweep_train_trajectories: 20,
            sweep_test_trajectories: 4,
            sweep_states: 101,
            noise: vec![0.0, 1.0, 5.0, 10.0],
            points: vec![100, 500, 1000, 5000, 10000],
        }
    }

    /// A few minutes: every experiment and figure, tiny data and epochs.
    pub fn quick() -> Self {
        Scale {
            name: "quick".into(),
            epochs: 10,
            family_epochs: 20,
            train_trajectories: 3,
            test_trajectories: 2,
            baseline_test_trajectories: 1,
            spring_states: 21,
            pendulum_states: 11,
            pendulum_dt: 1e-4,
            spring_sizes: vec![3, 5, 20],
            pendulum_sizes: vec![3, 5],
            baseline_spring_sizes: vec![5, 20],
            baseline_pendulum_sizes: vec![5],
            large_springs: vec![(500, 1)],
            peri_particles: 27,
            peri_train_trajectories: 2,
            peri_test_trajectories: 1,
            peri_states: 11,
            peri_epochs: 5,
            contact_balls: 9,
            contact_train_trajectories: 2,
            contact_test_trajectories: 1,
            contact_epochs: 5,
            sweep_epochs: 5,
            sweep_train_trajectories: 3,
            sweep_test_trajectories: 1,
            sweep_states: 11,
            noise: vec![0.0, 10.0],
            points: vec![100, 200],
        }
    }

    /// Overrides every epoch count (e.g. the paper's 10,000).
    pub fn with_epochs(mut self, epochs: usize) -> Self {
        self.epochs = epochs;
        self.family_epochs = epochs;
        self.peri_epochs = epochs;
        self.contact_epochs = epochs;
        self.sweep_epochs = epochs;
        self
    }
}
