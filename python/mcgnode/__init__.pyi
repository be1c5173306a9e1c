"""Type hints of the mcgnode package (the native module mcgnode._mcgnode)."""

import os
from typing import Any, Dict, List, Literal, Mapping, Optional, Sequence, Tuple, Union

from typing_extensions import TypedDict, Unpack

import numpy as np
import numpy.typing as npt

__version__: str
__all__ = ["Error", "Model", "__version__", "load_model", "read_bag", "train"]

PathLike = Union[str, "os.PathLike[str]"]
ArrayLike = npt.ArrayLike
F64 = npt.NDArray[np.float64]

class Error(Exception):
    """A failure of the mcgnode library: a bag it cannot read, a model file
    that does not load, data a model was not trained for, a rollout that
    diverged. The message is the one the ``mcgnode`` command line prints after
    ``error: ``."""

# One trajectory as read_bag returns it. Keys:
#   id: int, system: str, dim: int,
#   positions, velocities: (states, particles, dim) float64,
#   accelerations: (states, particles, dim) float64 or None,
#   stamps: (states,) float64 seconds from the first stamp,
#   masses: (particles,) float64, types: (particles,) uint32,
#   edges: (edges, 5) float64 rows (a, b, kind, rest_length, stiffness),
#          b >= particles meaning anchor b - particles, kind 0 spring / 1 bar,
#   anchors: (anchors, dim) float64,
#   interaction_radius: float (0: fixed edges only),
#   kinematic: (particles,) bool (True: motion given, never predicted),
#   periodic_box: None or {"lower", "upper": (dim,) float64,
#                 "periodic": (dim,) bool} (rollout wraps positions in it),
#   field: {"gravity": float, "drag": float, "force": list[float]} or None,
#   dt: float or None, save_every: int (mcgnode rollout --initial's defaults),
#   velocities_derived: bool.
Trajectory = Dict[str, Any]

# A rollout: positions and velocities (steps // every + 1, particles, dim)
# float64, stamps (steps // every + 1,) seconds.
RolloutResult = Dict[str, F64]

def read_bag(
    path: Union[PathLike, Sequence[PathLike]], topic: Optional[str] = None
) -> List[Trajectory]:
    """The ParticleState trajectories of a bag (an MCAP file, a rosbag2
    directory with MCAP or sqlite3 storage, a .db3 file, or a list of them),
    read as ``mcgnode`` reads them. ``topic`` chooses among several
    ParticleState topics. Raises Error when the bag cannot be read."""

def load_model(ref: PathLike) -> Model:
    """Loads a model as ``mcgnode rollout --model REF`` does: a model file
    (GNODE family or a baseline), ``"still"`` or ``"truth:<system>"``.
    Raises Error with the library's message."""

# One lr_drop: (epoch, lr), or "EPOCH:LR" as on the command line.
LrDrop = Union[Tuple[int, float], str]
# One block's hidden sizes: a list, one size, or "16,16".
BlockSizes = Union[Sequence[int], int, str]

class TrainOptions(TypedDict, total=False):
    """train()'s keywords: ``mcgnode train``'s options, dashes as underscores
    (see ``mcgnode train --help``); each left out, or None, keeps the default"""
    topic: str
    recipe: Literal["auto", "paper"]
    epochs: int
    seed: int
    lr: float
    lr_drop: Union[LrDrop, Sequence[LrDrop]]
    batch: int
    max_seconds: float
    patience: int
    hidden: int
    embed: int
    rounds: int
    arch: Literal["authors", "paper"]
    hidden_layers: int
    messages: Literal["linear", "mlp"]
    edge_update: Literal["concat", "product"]
    block_hidden: Union[Mapping[str, BlockSizes], Sequence[Union[Tuple[str, BlockSizes], str]]]
    noise: float
    points: int
    body_force: Literal["auto", "on", "off"]
    engine: Literal["native", "candle"]
    threads: int
    edge_physics: bool
    radius: float
    no_normalize: bool
    init: PathLike
    checkpoint: PathLike
    checkpoint_every: float
    ensemble: int
    quiet: bool

def train(
    bags: Union[PathLike, Sequence[PathLike]],
    out: PathLike,
    *,
    variant: str,
    **options: Unpack[TrainOptions],
) -> Dict[str, Any]:
    """``mcgnode train --data BAGS --out OUT --model VARIANT [options]``,
    options as keywords with underscores (``epochs=300``, ``seed=1``,
    ``recipe="paper"``, ``edge_physics=True``, ``lr_drop=[(300, 1e-3)]``,
    ``block_hidden={"edge_out": [16, 16]}``, ``quiet=True``, ...; see
    TrainOptions), turned into the library's typed options from the CLI's
    defaults. Writes the model file and returns its training report as a
    dict, with "out", "summary" and "explained_line". Raises Error with the
    CLI's message; an unknown keyword raises TypeError, a bad value
    ValueError naming its keyword."""

class Model:
    """A loaded model (see load_model)."""

    @property
    def reference(self) -> str:
        """The reference it was loaded from."""
    @property
    def name(self) -> str:
        """Its kind: "mcgnode", "gnode", ..., "lgn", "still", "truth:spring", ..."""
    @property
    def predicts_forces(self) -> bool:
        """Whether forces() answers (CGNODE, CDGNODE, MCGNODE, truth, still)."""
    @property
    def members(self) -> int:
        """Models averaged in its predictions: K for a file trained with
        ``--ensemble K``, else 1."""
    def describe(self) -> str:
        """A one-line description of the model."""
    def rollout(
        self,
        trajectory: Mapping[str, Any],
        steps: int,
        dt: Optional[float] = None,
        every: int = 1,
        *,
        kinematic_positions: Optional[ArrayLike] = None,
    ) -> RolloutResult:
        """Rolls out from the first state of ``trajectory`` (a read_bag dict)
        for ``steps`` steps of ``dt`` (default: the trajectory's ``dt``),
        keeping every ``every``-th state: ``mcgnode rollout --initial``, bit
        for bit. Contacts (``interaction_radius``) and kinematic particles
        come from the dict; ``kinematic_positions`` (steps + 1, kinematic
        particles, dim) moves the kinematic particles along it (velocities by
        central differences), else they are held. Checks the graph and field
        against what the model was trained on; a start out of its training
        range warns (RuntimeWarning). The result has "positions" and
        "velocities" (states, particles, dim) and "stamps"; an ensemble's
        also "spread" (states, particles): its members' standard deviation of
        position, per particle and state."""
    def rollout_arrays(
        self,
        positions: ArrayLike,
        velocities: ArrayLike,
        masses: ArrayLike,
        edges: ArrayLike,
        anchors: Optional[ArrayLike] = None,
        *,
        steps: int,
        dt: float,
        types: Optional[ArrayLike] = None,
        every: int = 1,
        interaction_radius: float = 0.0,
        kinematic: Optional[ArrayLike] = None,
        kinematic_positions: Optional[ArrayLike] = None,
    ) -> RolloutResult:
        """rollout from arrays: positions, velocities (particles, dim), masses
        (particles,), edges (edges, 5), anchors (anchors, dim), types
        (particles,; default 0), the interaction radius, kinematic flags
        (particles,) and the kinematic particles' given positions
        (steps + 1, kinematic particles, dim) as in ``rollout``."""
    def accelerations(
        self,
        positions: ArrayLike,
        velocities: ArrayLike,
        masses: ArrayLike,
        edges: ArrayLike,
        anchors: Optional[ArrayLike] = None,
        *,
        types: Optional[ArrayLike] = None,
    ) -> F64:
        """The model's accelerations at one state (particles, dim) or a stack
        of states (k, particles, dim); the result has their shape."""
    def forces(
        self,
        positions: ArrayLike,
        velocities: ArrayLike,
        masses: ArrayLike,
        edges: ArrayLike,
        anchors: Optional[ArrayLike] = None,
        *,
        types: Optional[ArrayLike] = None,
    ) -> Dict[str, npt.NDArray[Any]]:
        """The forces the model predicts at one state: "total" (particles,
        dim), "pairs" (pairs, 2) int64 rows (a, b) and "pair_forces" (pairs,
        dim), the force on a due to b, b feeling its opposite (MCGNODE and
        truth; none for CGNODE and CDGNODE). Models that predict accelerations (NODE, GNODE, baselines)
        raise Error."""
