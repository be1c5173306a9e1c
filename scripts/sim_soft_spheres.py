#!/usr/bin/env python3
"""Hertzian soft spheres in a box of fixed wall particles, simulated in numpy and written by rosbags: contact data mcgnode did not make.

Usage: sim_soft_spheres.py OUT [--balls 9] [--trajectories 20] [--states 101] [--seed 0]
                           [--dim 2|3] [--storage mcap|sqlite3]

Independent of mcgnode's code (and of `mcgnode simulate --system soft-spheres`,
whose law is the harmonic 1/2 k_c (R - r)^2): its own contact law, the Hertzian
repulsion V(r) = EPS (1 - r/R)^(5/2) for r < R (EPS 50, R 0.8; its force grows
as the overlap^(3/2), not linearly), its own balls (mass 0.7, type 0), its own
gravity (2.5 along -y), its own box (a free region of about 3 R^dim per ball,
1.5 times as tall as wide, walls at distance R from it, so a ball touches a wall
only by entering the margin; the walls are rows (2D) or sheets (3D) of
kinematic particles about 0.45 R apart, type 1, mass 1, listed BEFORE the
balls), its own initial states (balls placed uniformly at random in the free
region by rejection so that no two are closer than R, i.e. no contact at
t = 0, velocities Gaussian with sigma 1 per component), its own integrator
(velocity Verlet, dt 5e-4, every 40th state saved, so 0.02 s between states;
the walls are never integrated) and its own writer (rosbags' rosbag2 writer,
types registered from msg/ParticleState.msg). No `mcgnode` metadata record is
written: the messages say everything (interaction_radius R, one kinematic flag
per particle, field_status KNOWN with gravity (0, -2.5, 0), no drag, no force,
no edges). Accelerations are left empty, as a tool that records only the state
writes them. Before writing, every trajectory is checked: energy (kinetic +
contact + m g y of the balls) drifts by at most 1e-4 of its start value over
the whole trajectory (the largest drift is printed; halving dt divides it by
about 4, as Verlet's should), the walls never moved, and no ball left the box.
Run with the project's venv: .venv/bin/python3 (scripts/setup_venv.sh creates it).
"""

import argparse
import sys
from pathlib import Path

import numpy as np

RADIUS = 0.8  # interaction radius R: centres closer than this repel
EPS = 50.0  # energy scale of the Hertzian law V = EPS (1 - r/R)^(5/2)
BALL_MASS = 0.7
WALL_MASS = 1.0  # any positive value: walls are never integrated
GRAVITY = 2.5  # along -y
WALL_STEP = 0.45 * RADIUS  # wall particles' spacing (at most)
AREA_PER_BALL = 3.0  # free region per ball, in units of R^dim
ASPECT = 1.5  # free region's height / width
V_SIGMA = 1.0  # initial velocity per component
DT = 5e-4
EVERY = 40
# Largest relative energy drift accepted. Measured with these constants: at
# most 7.4e-6 over 40 trajectories of 2 s (halving dt divides it by about 4);
# 1e-4 leaves a margin of 13x and still stops a broken force or a dt too large
# for the contacts (dt 1e-2 drifts by 4e-4 and is refused).
MAX_DRIFT = 1e-4


def box(balls, dim):
    """The box: lower and upper corners of the free region and the walls' planes."""
    side = (AREA_PER_BALL * balls / ASPECT) ** (1.0 / dim) * RADIUS
    free = np.full(dim, side)
    free[1] *= ASPECT
    lo = np.full(dim, RADIUS)  # walls at 0 and free + 2R on every axis
    return lo, lo + free, free + 2.0 * RADIUS


def axis_points(length):
    k = int(np.ceil(length / WALL_STEP))
    return np.linspace(0.0, length, k + 1)


def walls(size):
    """Wall particles on the surface of the box [0, size]: every grid point of
    the surface (spacing at most WALL_STEP per axis), each once."""
    axes = [axis_points(s) for s in size]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(size))
    on_surface = np.zeros(len(grid), dtype=bool)
    for c, s in enumerate(size):
        on_surface |= (grid[:, c] == 0.0) | (grid[:, c] == s)
    return grid[on_surface]


def pair_forces(diff):
    """Hertzian repulsion on the first of each pair, given diff = q_first - q_second (..., dim)."""
    r = np.linalg.norm(diff, axis=-1)
    touching = r < RADIUS
    overlap = np.where(touching, 1.0 - r / RADIUS, 0.0)
    # -dV/dr = (5/2) (EPS/R) (1 - r/R)^(3/2), along diff / r.
    mag = np.where(touching, 2.5 * EPS / RADIUS * overlap**1.5 / np.where(touching, r, 1.0), 0.0)
    return mag[..., None] * diff


def accelerations(qb, qw):
    """Accelerations of the balls: contacts with other balls and with walls, and gravity."""
    bb = qb[:, None, :] - qb[None, :, :]
    diag = np.arange(len(qb))
    bb[diag, diag] = 2.0 * RADIUS  # no self-interaction (a distance beyond R)
    f = pair_forces(bb).sum(axis=1) + pair_forces(qb[:, None, :] - qw[None, :, :]).sum(axis=1)
    acc = f / BALL_MASS
    acc[:, 1] -= GRAVITY
    return acc


def energy(qb, vb, qw):
    """Kinetic + contact + gravitational energy (y measured from the floor), > 0."""
    i, j = np.triu_indices(len(qb), k=1)
    r_bb = np.linalg.norm(qb[i] - qb[j], axis=-1)
    r_bw = np.linalg.norm(qb[:, None, :] - qw[None, :, :], axis=-1).ravel()
    r = np.concatenate([r_bb, r_bw])
    contact = EPS * np.sum(np.clip(1.0 - r / RADIUS, 0.0, None) ** 2.5)
    return 0.5 * BALL_MASS * np.sum(vb * vb) + contact + BALL_MASS * GRAVITY * np.sum(qb[:, 1])


def start(rng, balls, lo, hi):
    """Balls uniform in the free region, no two closer than R (rejection)."""
    dim = len(lo)
    for _ in range(1000):
        q = np.empty((0, dim))
        for _ in range(200 * balls):
            p = rng.uniform(lo, hi)
            if len(q) == 0 or np.min(np.linalg.norm(q - p, axis=1)) >= RADIUS:
                q = np.vstack([q, p])
                if len(q) == balls:
                    return q, rng.normal(0.0, V_SIGMA, q.shape)
    sys.exit(f"could not place {balls} balls without overlap")


def trajectory(rng, balls, lo, hi, size, qw, states):
    qb, vb = start(rng, balls, lo, hi)
    qw0 = qw.copy()
    acc = accelerations(qb, qw)
    e0 = energy(qb, vb, qw)
    out = [(qb.copy(), vb.copy())]
    drift = 0.0
    for _ in range(states - 1):
        for _ in range(EVERY):
            v_half = vb + 0.5 * DT * acc
            qb = qb + DT * v_half
            acc = accelerations(qb, qw)
            vb = v_half + 0.5 * DT * acc
        out.append((qb.copy(), vb.copy()))
        drift = max(drift, abs(energy(qb, vb, qw) - e0) / e0)
    if not np.array_equal(qw, qw0):
        sys.exit("a wall moved")
    inside = all(np.all((q > 0.0) & (q < size)) for q, _ in out)
    return out, drift, inside


def typestore():
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_KILTED)
    text = (Path(__file__).resolve().parent.parent / "msg" / "ParticleState.msg").read_text()
    store.register(get_types_from_msg(text, "mcgnode_msgs/msg/ParticleState"))
    return store


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--balls", type=int, default=9)
    ap.add_argument("--trajectories", type=int, default=20)
    ap.add_argument("--states", type=int, default=101)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--dim", type=int, choices=[2, 3], default=2)
    ap.add_argument("--storage", choices=["mcap", "sqlite3"], default="mcap")
    args = ap.parse_args()
    if args.balls < 1 or args.trajectories < 1 or args.states < 3:
        sys.exit("need --balls >= 1, --trajectories >= 1, --states >= 3")
    if args.out.exists():
        sys.exit(f"{args.out} exists already")

    from rosbags.rosbag2 import StoragePlugin, Writer

    store = typestore()
    T = "mcgnode_msgs/msg/ParticleState"
    PS = store.types[T]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    V3 = store.types["geometry_msgs/msg/Vector3"]

    d = args.dim
    lo, hi, size = box(args.balls, d)
    qw = walls(size)
    nw, n = len(qw), len(qw) + args.balls
    kinematic = np.arange(n) < nw
    types = kinematic.astype(np.uint32)
    masses = np.where(kinematic, WALL_MASS, BALL_MASS)
    zeros = np.zeros((n, 3))

    def vec3(rows):
        return [V3(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in rows]

    def padded(a):
        out = np.zeros((len(a), 3))
        out[:, :d] = a
        return out

    rng = np.random.default_rng(args.seed)
    runs, worst = [], 0.0
    for tid in range(args.trajectories):
        states, drift, inside = trajectory(rng, args.balls, lo, hi, size, qw, args.states)
        worst = max(worst, drift)
        if drift > MAX_DRIFT or not inside:
            sys.exit(f"trajectory {tid}: energy drift {drift:.2e}, every ball inside: {inside}")
        runs.append(states)

    plugin = StoragePlugin.MCAP if args.storage == "mcap" else StoragePlugin.SQLITE3
    writer = Writer(args.out, version=9, storage_plugin=plugin)
    writer.open()
    conn = writer.add_connection("/spheres/state", T, typestore=store)
    wall_rows = padded(qw)
    for tid, states in enumerate(runs):
        for step, (qb, vb) in enumerate(states):
            t = tid * 1000.0 + step * DT * EVERY
            ns = int(round(t * 1e9))
            msg = PS(
                header=Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="box"),
                trajectory_id=tid,
                step=step,
                system="hertz-spheres",
                dimension=d,
                types=types,
                masses=masses,
                positions=vec3(np.vstack([wall_rows, padded(qb)])),
                velocities=vec3(np.vstack([zeros[:nw], padded(vb)])),
                accelerations=[],
                edge_a=np.zeros(0, dtype=np.uint32),
                edge_b=np.zeros(0, dtype=np.uint32),
                edge_kind=np.zeros(0, dtype=np.uint8),
                edge_rest_length=np.zeros(0),
                edge_stiffness=np.zeros(0),
                anchors=[],
                field_status=1,
                gravity=V3(x=0.0, y=-GRAVITY, z=0.0),
                drag=0.0,
                force=V3(x=0.0, y=0.0, z=0.0),
                interaction_radius=RADIUS,
                kinematic=kinematic,
                box_lower=V3(x=0.0, y=0.0, z=0.0),
                box_upper=V3(x=0.0, y=0.0, z=0.0),
                box_periodic=np.zeros(0, dtype=bool),
            )
            writer.write(conn, ns, bytes(store.serialize_cdr(msg, T)))
    writer.close()
    print(
        f"{args.out}: {args.trajectories} trajectories of {args.balls} balls and {nw} wall "
        f"particles ({d}D, box {' x '.join(f'{s:.3g}' for s in size)}, R {RADIUS:g}), "
        f"{args.states} states every {DT * EVERY:g} s; worst energy drift {worst:.1e}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
