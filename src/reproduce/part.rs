//! The parts of `reproduce` ([`Part`]): their names on the command line and
//! the experiment each runs.

use super::experiments::{self, Section};
use super::lab::Lab;
use super::scale::Scale;
use crate::error::Result;

/// The parts of `reproduce`, each one section of the report.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// The 5-spring: biases, baselines, architecture, zero-shot sizes.
    Springs,
    /// The 5-pendulum: the same.
    Pendulums,
    /// The 3D peridynamic solid.
    Peridynamic,
    /// Springs under drag or an external force.
    DragForce,
    /// Training-data noise.
    Noise,
    /// Training-set size.
    DataEfficiency,
    /// Systems that touch (not in the paper): MCGNODE, GNODE and GNS on
    /// contact edges.
    Contacts,
}

impl crate::names::Named for Part {
    const ALL: &'static [Self] = &[
        Part::Springs,
        Part::Pendulums,
        Part::Peridynamic,
        Part::DragForce,
        Part::Noise,
        Part::DataEfficiency,
        Part::Contacts,
    ];
    const WHAT: &'static str = "reproduce part";

    fn name(self) -> &'static str {
        match self {
            Part::Springs => "springs",
            Part::Pendulums => "pendulums",
            Part::Peridynamic => "peridynamic",
            Part::DragForce => "drag-force",
            Part::Noise => "noise",
            Part::DataEfficiency => "data-efficiency",
            Part::Contacts => "contacts",
        }
    }
}

crate::impl_named!(Part);

impl Part {
    /// Runs this part.
    pub(super) fn run(self, lab: &Lab, sc: &Scale) -> Result<Section> {
        use crate::physics::SystemKind;
        match self {
            Part::Springs => experiments::main_comparison(lab, sc, SystemKind::Spring),
            Part::Pendulums => experiments::main_comparison(lab, sc, SystemKind::Pendulum),
            Part::Peridynamic => experiments::peridynamic(lab, sc),
            Part::DragForce => experiments::drag_and_force(lab, sc),
            Part::Noise => experiments::noise(lab, sc),
            Part::DataEfficiency => experiments::data_efficiency(lab, sc),
            Part::Contacts => experiments::contacts(lab, sc),
        }
    }
}
