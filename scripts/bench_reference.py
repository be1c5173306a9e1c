#!/usr/bin/env python3
"""Side-by-side speed harness: the authors' JAX code (a user-made checkout of
M3RG-IITD/graph_neural_ODE) against `mcgnode bench`. Driven by
scripts/bench_vs_reference.sh, which makes the venv; see that script's header.

None of the authors' code is kept here. At run time `prepare` copies the few
files the MCGNODE runs need out of REF_DIR into a work directory and edits the
copies (a handful of one-line edits, each listed with its reason and printed),
and `job` runs one of those copies in the venv with shims for the jax/jax-md
API changes since their release (monkeypatched at import, also listed).

Their LGN and HGN come from a second checkout, of M3RG-IITD/benchmarking_graph
(the same group's NeurIPS 2022 benchmark, whose full-graph LGN and HGN the
paper's baselines are), when the harness is given one (`--baselines`).

Subcommands:
  prepare REF WORK [--baselines REF2 WORK2]
                            adapted copies of their scripts (system python)
  job WORK NAME OUT ...     one JAX measurement, run by the venv's python
  harness ...               the interleaved rounds and the table (system python)
"""

import argparse
import datetime
import json
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))

# ---------------------------------------------------------------------------
# What the harness changes in (copies of) their scripts, and why. Each edit is
# (file, old line text, new line text, reason); `old` must occur exactly once.
# ---------------------------------------------------------------------------
TIMED_EPOCHS = "for epoch in __mcgnode_bench__.epochs(range(epochs)):"
TIMED_ROLLOUT = "pred_traj = __mcgnode_bench__.rollout(sim_model, R, V)"
NO_GT = "actual_traj = None  # mcgnode-bench: ground truth not simulated"
EDITS = [
    ("Spring-data.py", "stride = 100", "stride = 10",
     "data only feeds the timed epochs (their cost depends on the data's size, "
     "100 x 100 states, not on how far apart the states lie): 10x fewer steps"),
    ("Pendulum-data.py", "stride = 1000", "stride = 10",
     "as above: 100x fewer steps of their constrained simulator, same size"),
    ("Spring-4MCGNODE.py", "for epoch in range(epochs):", TIMED_EPOCHS,
     "times each epoch (blocked on the parameters and the validation loss) "
     "and stops after the timed ones"),
    ("Pendulum-4MCGNODE.py", "for epoch in range(epochs):", TIMED_EPOCHS,
     "as above"),
    ("Spring-4MCGNODE-post.py", "pred_traj = sim_model(R, V)", TIMED_ROLLOUT,
     "times their jitted rollout (one untimed call compiles it; each timed "
     "call is blocked until done) and stops"),
    ("Pendulum-4MCGNODE-post.py", "pred_traj = sim_model(R, V)", TIMED_ROLLOUT,
     "as above"),
    ("Spring-4MCGNODE-post.py", "actual_traj = sim_orig2(R, V)  # full_traj[start_:stop_]",
     NO_GT, "their ground-truth simulation (a dense mass-matrix solve, hours at "
     "500 springs) is not what is timed"),
    ("Pendulum-4MCGNODE-post.py", "actual_traj = sim_orig2(R, V)  # full_traj[start_:stop_]",
     NO_GT, "as above"),
]
SHIMS = [
    "jax.experimental.optimizers -> jax.example_libraries.optimizers (moved in jax 0.2.25)",
    "`from jax.config import config` -> a module `jax.config` holding jax.config (the module is gone)",
    "jax.ops.index_update(x, i, v) -> x.at[i].set(v); jax.ops.index -> jnp.index_exp (removed in jax 0.4)",
    "jax.tree_map -> jax.tree_util.tree_map (removed in jax 0.6)",
    "jax.ops.segment_sum(..., num_segments=n_node) with n_node a 1-element array -> "
    "its one integer (jax now takes only a scalar)",
    "jnp.clip(x, a_min=, a_max=) -> jnp.clip(x, min=, max=) (the old keywords were removed)",
    "jax_md.quantity.canonicalize_mass(m) (gone from jax-md 0.2.29) -> a mass of shape "
    "[n] reshaped to [n, 1], a scalar kept, as it did",
    "note, no change: jax-md's NVEState now holds momentum where theirs put the velocity; "
    "its .velocity divides by the mass, which is 1 in all these scripts: same values",
    "shadow.plot (the authors' private plotting package, not on PyPI) -> a stub: "
    "panel() = matplotlib subplots (Agg), xlabel/ylabel/title on an axis",
    "src.io.loadfile of `fgnode_trained_model*` in a rollout job -> the parameters "
    "their training script saved in this run (the file names of their training and "
    "post scripts disagree for pendulums; the values do not change a step's cost)",
]
NEEDED = ["Spring-data.py", "Pendulum-data.py", "Spring-4MCGNODE.py",
          "Pendulum-4MCGNODE.py", "Spring-4MCGNODE-post.py",
          "Pendulum-4MCGNODE-post.py"]
# Their GNODE repository's LGN and HGN are not timed (their LGN and HGN come
# from benchmarking_graph instead, see BASELINE_EDITS): that code (b5add1f)
# has neither in a runnable form. Spring-5LGN.py trains a full graph network
# that outputs accelerations (`fgn.cal_acceleration`; the commit that added it, 77262b2,
# calls these scripts "FGNs"): its Lagrangian path is commented out and the
# `Lmodel` it would pass to `lnn.accelerationFull` is defined nowhere.
# Spring-6HGN.py calls fgn.cal_l and Spring-6HGN-our.py
# L_gnode_cal_force_q_qdot, neither defined in their code: both stop with an
# error before the first epoch. (Until 2026-12-03 the harness timed
# Spring-5LGN.py against mcgnode's LGN: a different model, so no ratio.)


# Their LGN and HGN, from a checkout of M3RG-IITD/benchmarking_graph: its
# Spring-LGN.py and Spring-HGN.py train full graph networks that give the
# Lagrangian (accelerations by Euler-Lagrange, Hessian in qdot included) and
# the Hamiltonian, with the paper's sizes (embeddings 8, hidden 16, one round).
BASELINE_EDITS = [
    ("Spring-data.py", "stride = 100", "stride = 10", "as for their GNODE data above"),
    ("Spring-data.py",
     'rstring = datetime.now().strftime("%m-%d-%Y_%H-%M-%S") if rname else "0_10000"',
     'rstring = datetime.now().strftime("%m-%d-%Y_%H-%M-%S") if rname else "0"',
     "their data script writes to .../0_10000/, the LGN script reads .../0/"),
    ("Spring-data-HGNN.py",
     'rstring = datetime.now().strftime("%m-%d-%Y_%H-%M-%S") if rname else "2_" + str(nconfig * runs)',
     'rstring = datetime.now().strftime("%m-%d-%Y_%H-%M-%S") if rname else "2"',
     "their data script writes to .../2_10000/, the HGN script reads .../2/"),
    ("Spring-LGN.py", "for epoch in range(epochs):", TIMED_EPOCHS, "as for MCGNODE"),
    ("Spring-HGN.py", "for epoch in range(epochs):", TIMED_EPOCHS, "as for MCGNODE"),
]
BASELINE_NEEDED = ["Spring-data.py", "Spring-data-HGNN.py", "Spring-LGN.py", "Spring-HGN.py"]
# Directories their training scripts write to without making them.
BASELINE_DIRS = ["5-spring-training-time", "5-spring-training-loss"]


def prepare(ref, work, needed, edits, dirs=()):
    scripts = os.path.join(ref, "scripts")
    for f in needed:
        if not os.path.isfile(os.path.join(scripts, f)):
            sys.exit(f"bench: {ref} has no scripts/{f}: not a checkout of the "
                     "authors' repository it should be (see --help)")
    for d in ["src", "scripts"]:
        shutil.rmtree(os.path.join(work, d), ignore_errors=True)
    shutil.copytree(os.path.join(ref, "src"), os.path.join(work, "src"))
    os.makedirs(os.path.join(work, "scripts"))
    shutil.copytree(os.path.join(scripts, "psystems"),
                    os.path.join(work, "scripts", "psystems"))
    for d in dirs:
        os.makedirs(os.path.join(work, d), exist_ok=True)
    texts = {f: open(os.path.join(scripts, f)).read() for f in needed}
    print(f"adapted copy of {ref} in {work}; edits to the copies:")
    for f, old, new, why in edits:
        lines = texts[f].split("\n")
        hits = [i for i, l in enumerate(lines) if l.strip() == old]
        if len(hits) != 1:
            sys.exit(f"bench: expected one line `{old}` in scripts/{f}, found "
                     f"{len(hits)}: their code changed; update EDITS in {__file__}")
        i = hits[0]
        indent = lines[i][: len(lines[i]) - len(lines[i].lstrip())]
        lines[i] = indent + new
        texts[f] = "\n".join(lines)
        print(f"  scripts/{f}:{i + 1}: `{old}` -> `{new}`\n      ({why})")
    for f, t in texts.items():
        with open(os.path.join(work, "scripts", f), "w") as fh:
            fh.write(t)


# ---------------------------------------------------------------------------
# The JAX side: one measurement per process (run by the venv's python).
# ---------------------------------------------------------------------------
def install_shims(params_file):
    import types
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    import jax
    import jax.numpy as jnp
    import jax.example_libraries.optimizers as optimizers
    import jax.experimental

    jax.experimental.optimizers = optimizers
    sys.modules["jax.experimental.optimizers"] = optimizers
    cfg = types.ModuleType("jax.config")
    cfg.config = jax.config
    sys.modules["jax.config"] = cfg
    jax.ops.index_update = lambda x, idx, y: jnp.asarray(x).at[idx].set(y)
    jax.ops.index = jnp.index_exp
    if not hasattr(jax, "tree_map"):
        jax.tree_map = jax.tree_util.tree_map
    clip = jnp.clip

    def clip_old(x, *args, a_min=None, a_max=None, **kw):
        if a_min is not None:
            kw["min"] = a_min
        if a_max is not None:
            kw["max"] = a_max
        return clip(x, *args, **kw)

    jnp.clip = clip_old
    seg = jax.ops.segment_sum

    def segment_sum(data, segment_ids, num_segments=None, *a, **kw):
        if num_segments is not None and np.ndim(num_segments) == 1 and np.size(num_segments) == 1:
            num_segments = int(np.asarray(num_segments)[0])
        return seg(data, segment_ids, num_segments, *a, **kw)

    jax.ops.segment_sum = segment_sum
    import jax_md.quantity
    if not hasattr(jax_md.quantity, "canonicalize_mass"):
        def canonicalize_mass(mass):
            if isinstance(mass, float) or jnp.ndim(mass) == 0:
                return mass
            if mass.ndim == 1:
                return jnp.reshape(mass, (mass.shape[0], 1))
            if mass.ndim == 2 and mass.shape[1] == 1:
                return mass
            raise ValueError(f"mass of shape {mass.shape}")
        jax_md.quantity.canonicalize_mass = canonicalize_mass

    shadow = types.ModuleType("shadow")
    sp = types.ModuleType("shadow.plot")

    def panel(r, c, figsize=None, **_):
        return plt.subplots(r, c, figsize=figsize)

    def _on(f):
        return lambda text, ax=None, **kw: getattr(ax or plt.gca(), f)(text)

    sp.panel, sp.plt, sp.np, sp.os = panel, plt, np, os
    sp.xlabel, sp.ylabel, sp.title = _on("set_xlabel"), _on("set_ylabel"), _on("set_title")
    sp.__all__ = ["panel", "plt", "np", "os", "xlabel", "ylabel", "title"]
    shadow.plot = sp
    sys.modules["shadow"] = shadow
    sys.modules["shadow.plot"] = sp

    if params_file:
        sys.path.insert(0, ".." )
        import src.io
        orig = src.io.loadfile

        def loadfile(filename, *a, **kw):
            if "fgnode_trained_model" in os.path.basename(filename):
                return orig(params_file, *a, **kw)
            return orig(filename, *a, **kw)

        src.io.loadfile = loadfile


class Bench:
    """The hooks the edited lines call (as builtins `__mcgnode_bench__`)."""

    def __init__(self, out, reps, what):
        self.out, self.reps, self.what = out, reps, what
        self.samples = []
        self.t_start = time.perf_counter()

    @staticmethod
    def _now():
        r = resource.getrusage(resource.RUSAGE_SELF)
        return time.perf_counter(), r.ru_utime, r.ru_stime

    def _add(self, a, b):
        self.samples.append({"wall": b[0] - a[0], "user": b[1] - a[1], "sys": b[2] - a[2]})

    def finish(self):
        import jax
        doc = {"what": self.what, "samples": self.samples,
               "jax": jax.__version__, "devices": str(jax.devices()),
               "process_wall": time.perf_counter() - self.t_start}
        with open(self.out, "w") as fh:
            json.dump(doc, fh)
        sys.stdout.flush()
        os._exit(0)  # their loops catch every exception; stop here, timed work done

    def epochs(self, it):
        import jax
        frame = sys._getframe(1)
        t0 = None
        for i, e in enumerate(it):
            if i > 0:
                loc = frame.f_locals
                jax.block_until_ready((loc["params"], loc["ltarray"][-1]))
                t1 = self._now()
                if i > 1:  # epoch 0 compiles and saves: not timed
                    self._add(t0, t1)
                if i == 1 + self.reps:
                    self.finish()
                t0 = self._now()
            yield e
        self.finish()

    def rollout(self, sim, R, V):
        import jax
        out = jax.block_until_ready(sim(R, V))  # compiles
        for _ in range(self.reps):
            a = self._now()
            out = jax.block_until_ready(sim(R, V))
            self._add(a, self._now())
        self.finish()
        return out


def job(args):
    import builtins
    import runpy
    work = os.path.abspath(args.work)
    os.chdir(os.path.join(work, "scripts"))
    sys.path[:0] = [os.path.join(work, "scripts"), work]
    install_shims(args.params)
    builtins.__mcgnode_bench__ = Bench(args.out, args.reps, args.script)
    sys.argv = [args.script] + args.rest
    runpy.run_path(args.script, run_name="__main__")
    sys.exit("bench: their script ended without reaching the timed part")


# ---------------------------------------------------------------------------
# The harness (system python): interleaved rounds, medians, one table.
# ---------------------------------------------------------------------------
class Runner:
    def __init__(self, a):
        self.a = a
        self.log = open(os.path.join(a.work, "bench.log"), "a")

    def run(self, cmd, env=None, timeout=3600, cwd=None, capture=False):
        """Runs cmd (its output to the log, or stdout returned with `capture`);
        returns (stdout, wall, user, sys) of the whole process."""
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        self.log.write(f"\n$ {' '.join(cmd)}\n")
        self.log.flush()
        p = subprocess.run(cmd, env=env, cwd=cwd, timeout=timeout,
                           stdout=subprocess.PIPE if capture else self.log,
                           stderr=self.log, text=True)
        wall = time.perf_counter() - t0
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        if p.returncode != 0:
            sys.exit(f"bench: `{' '.join(cmd)}` failed ({p.returncode}); see "
                     f"{self.log.name}")
        return p.stdout, wall, r1.ru_utime - r0.ru_utime, r1.ru_stime - r0.ru_stime


JAX_ENV = {
    1: ({"XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"}, "0"),
    2: ({}, "0,1"),
}


def jax_items(quick):
    reps_e = 1 if quick else 5
    reps_r = 1 if quick else 3
    return [
        # key, label, script, fire args, repetitions, steps (None: epoch)
        ("spring_epoch", "5-spring MCGNODE epoch (10,000 states)", "Spring-4MCGNODE.py",
         ["--N=5", "--epochs=1000", "--rname=False", "--trainm=0"], reps_e, None),
        ("pendulum_epoch", "5-pendulum MCGNODE epoch (10,000 states)", "Pendulum-4MCGNODE.py",
         ["--N=5", "--epochs=1000", "--rname=False", "--trainm=1"], reps_e, None),
        ("spring_rollout", "5-spring rollout, 20,000 steps", "Spring-4MCGNODE-post.py",
         ["--N=5", "--useN=5", "--runs=200", "--stride=100", "--maxtraj=1"], reps_r, 20000),
        ("pendulum_rollout", "5-pendulum rollout, 100,000 steps", "Pendulum-4MCGNODE-post.py",
         ["--N=5", "--useN=5", "--runs=100", "--stride=1000", "--maxtraj=1"], reps_r, 100000),
        ("spring50", "50-spring rollout (40,000 steps)", "Spring-4MCGNODE-post.py",
         ["--N=50", "--useN=5", "--runs=400", "--stride=100", "--maxtraj=1"], reps_r, 40000),
        ("spring500", "500-spring rollout (4,000 steps)", "Spring-4MCGNODE-post.py",
         ["--N=500", "--useN=5", "--runs=40", "--stride=100", "--maxtraj=1"], reps_r, 4000),
    ]


def baseline_items(quick):
    """Their LGN and HGN epochs (benchmarking_graph; run in the baselines' work
    directory). `--if_noisy_data=0`: their default adds noise to the data,
    which does not change an epoch's cost, and writes elsewhere."""
    reps = 1 if quick else 3
    args = ["--N=5", "--epochs=1000", "--rname=False", "--if_noisy_data=0"]
    return [
        ("spring_lgn_epoch", "5-spring LGN epoch (10,000 states)", "Spring-LGN.py", args, reps, None),
        ("spring_hgn_epoch", "5-spring HGN epoch (10,000 states)", "Spring-HGN.py", args, reps, None),
    ]


BASELINE_KEYS = {item[0] for item in baseline_items(False)}

# mcgnode figure (a substring for `bench --only`, unique) for each row; the
# multi-thread epoch is named by the cores the binary sees (available_parallelism)
CORES = len(os.sched_getaffinity(0))
MCG = {
    "spring_epoch": ["5-spring mcgnode epoch, 10,000 states, native engine, 1 thread",
                     f"5-spring mcgnode epoch, 10,000 states, native engine, {CORES} thread"],
    "pendulum_epoch": ["5-pendulum mcgnode epoch, 10,000 states, native engine, 1 thread",
                       f"5-pendulum mcgnode epoch, 10,000 states, native engine, {CORES} thread"],
    "spring_rollout": ["5-spring mcgnode rollout, 20 s"],
    "pendulum_rollout": ["5-pendulum mcgnode rollout, 1 s"],
    "spring50": ["50-spring mcgnode rollout speed"],
    "spring500": ["500-spring mcgnode rollout speed"],
    # mcgnode's LGN and HGN on the native engine (1 thread and every core)
    # and on candle (the reference, which they trained on before).
    **{f"spring_{m}_epoch": [f"5-spring {m} epoch, 10000 states (native engine, 1 thread)",
                             f"5-spring {m} epoch, 10000 states (native engine, {CORES} thread)",
                             f"5-spring {m} epoch, 10000 states (candle)"]
       for m in ("lgn", "hgn")},
}


def flock_prefix(a):
    return ["flock", a.lock] if a.lock else []


def jax_job(r, a, item, threads):
    key, _, script, fargs, reps, _ = item
    extra, cpus = JAX_ENV[threads]
    env = dict(os.environ, **extra)
    env.pop("XLA_FLAGS", None) if not extra else None
    work = a.work2 if key in BASELINE_KEYS else a.work
    out = os.path.join(work, f"out-{key}-{threads}.json")
    cmd = flock_prefix(a) + ["taskset", "-c", cpus, a.venv_python, __file__, "job",
                             work, script, out, "--reps", str(reps)]
    if "post" in script:
        cmd += ["--params", params_file(a.work, script)]
    cmd += ["--"] + fargs
    _, pwall, puser, psys = r.run(cmd, env=env, timeout=a.timeout)
    doc = json.load(open(out))
    s = doc["samples"]
    med = lambda k: statistics.median(x[k] for x in s)
    return {"wall": med("wall"), "user": med("user"), "sys": med("sys"),
            "process": {"wall": pwall, "user": puser, "sys": psys}, "jax": doc["jax"]}


def params_file(work, script):
    sub = "a-5-Spring-4MCGNODE/0/fgnode_trained_model_0_0.dil" if script.startswith(
        "Spring") else "5-Pendulum-4MCGNODE/0/fgnode_trained_model_0_1.dil"
    return os.path.join(work, "results", sub)


def mcg_cpus(figure):
    """The CPUs a figure's process may run on: the rollouts (one thread) on
    CPU 0, as JAX's 1-thread runs, so that neither is moved between cores
    mid-run; the epochs on every CPU (`bench` names its all-cores epoch by
    the CPUs it sees, so pinned it would name two figures "1 thread"; candle's
    baseline epochs take the cores they find)."""
    if "thread" in figure or "epoch" in figure:
        return ",".join(str(c) for c in sorted(os.sched_getaffinity(0)))
    return "0"


def mcg_job(r, a, figure, quick):
    args = [a.mcgnode, "bench", "--json", "--only", figure]
    # `bench --quick` shrinks the baselines' data to 1,000 states (and renames
    # their figures): those run in full, a few seconds, even with --quick.
    if quick and "10000 states" not in figure:
        args.insert(2, "--quick")
    cmd = flock_prefix(a) + ["taskset", "-c", mcg_cpus(figure)] + args
    out, pwall, puser, psys = r.run(cmd, timeout=a.timeout, capture=True)
    doc = json.loads(out)
    figs = doc if isinstance(doc, list) else doc.get("figures", doc)
    if len(figs) != 1:
        sys.exit(f"bench: `--only {figure}` matched {len(figs)} figures")
    f = figs[0]
    v = f["value"] / 1e3 if f["unit"] == "ms" else f["value"]
    return {"value": v, "unit": f["unit"], "name": f["name"],
            "process": {"wall": pwall, "user": puser, "sys": psys}}


def fmt_range(vals, unit):
    med = statistics.median(vals)
    if unit == "steps/s":
        f = lambda x: f"{x / 1e3:.1f}"
        return f"{f(med)}k steps/s ({f(min(vals))}–{f(max(vals))}k)"
    if med < 1:
        f = lambda x: f"{x * 1e3:.1f}"
        return f"{f(med)} ms ({f(min(vals))}–{f(max(vals))})"
    f = lambda x: f"{x:.2f}"
    return f"{f(med)} s ({f(min(vals))}–{f(max(vals))})"


def secs(x):
    return f"{x * 1e3:.0f} ms" if x < 1 else f"{x:.2f} s"


def harness(a):
    rounds = 1 if a.quick else a.rounds
    r = Runner(a)
    items = jax_items(a.quick) + (baseline_items(a.quick) if a.work2 else [])
    # Their data sets (once; untimed): (work dir, data script, the file it
    # writes, its arguments). LGN reads the benchmark's Spring-data.py's,
    # HGN its Spring-data-HGNN.py's (positions and momenta).
    data = [(a.work, "Spring-data.py", "a-5-Spring-data/0", ["--N1=5"]),
            (a.work, "Pendulum-data.py", "5-Pendulum-data/0", ["--N=5"])]
    if a.work2:
        data += [(a.work2, "Spring-data.py", "5-Spring-data/0", ["--N1=5"]),
                 (a.work2, "Spring-data-HGNN.py", "5-Spring-data/2", ["--N=5", "--stride=10"])]
    for work, script, sub, args in data:
        if not os.path.exists(os.path.join(work, "results", sub, "model_states_0.pkl")):
            print(f"generating their data with {os.path.basename(os.path.dirname(work))}'s "
                  f"{script} {' '.join(args)} (once, untimed) ...", flush=True)
            r.run(flock_prefix(a) + [a.venv_python, __file__, "job", work, script,
                                     os.devnull, "--reps", "0", "--allow-end", "--"] + args,
                  timeout=a.timeout)
    res = {k[0]: {"jax1": [], "jax2": [], "mcg": {f: [] for f in MCG[k[0]]}} for k in items}
    info = {}
    for rnd in range(rounds):
        print(f"round {rnd + 1}/{rounds}", flush=True)
        for item in items:
            key = item[0]
            for f in MCG[key]:
                m = mcg_job(r, a, f, a.quick)
                res[key]["mcg"][f].append(m)
                print(f"  mcgnode {m['name']}: {m['value']:.4g} {'s' if m['unit'] == 'ms' else m['unit']}"
                      f"  (process wall {m['process']['wall']:.1f} s, user {m['process']['user']:.1f} s,"
                      f" sys {m['process']['sys']:.1f} s)", flush=True)
            for th in [1, 2]:
                j = jax_job(r, a, item, th)
                info["jax"] = j["jax"]
                res[key][f"jax{th}"].append(j)
                print(f"  JAX {th} thread(s) {key}: wall {j['wall']:.4g} s, user {j['user']:.3g} s,"
                      f" sys {j['sys']:.3g} s (process wall {j['process']['wall']:.1f} s)", flush=True)
    return res, items, info, rounds


def sha256(path):
    import hashlib
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def table(a, res, items, info, rounds):
    def git(d, *args):
        try:
            return subprocess.run(["git", "-C", d] + list(args), capture_output=True,
                                  text=True, timeout=10).stdout.strip()
        except Exception:
            return "?"
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    up = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    head = [f"date: {now}; rounds: {rounds} (interleaved mcgnode, JAX 1 thread, JAX 2 threads per row)",
            f"load before: {a.load_before}; after: {up}",
            f"mcgnode commit {a.commit_at_start} at the start"
            + (f" ({end} at the end)" if (end := git(HERE, 'rev-parse', '--short', 'HEAD'))
               != a.commit_at_start else "")
            + f"{' (dirty)' if git(HERE, 'status', '--porcelain', '--untracked-files=no') else ''}"
            f", binary {a.mcgnode} (sha256 {sha256(a.mcgnode)[:12]}: a build, matched by its hash)",
            f"REF_DIR commit {git(a.ref, 'rev-parse', '--short', 'HEAD')}; jax {info.get('jax')}"
            f", jax-md {a.jaxmd}"
            + (f"; LGN/HGN from benchmarking_graph at {git(a.ref2, 'rev-parse', '--short', 'HEAD')}"
               " (theirs: full graph networks for L(q, qdot) and H(q, p); mcgnode's: "
               "L = T - V(q), H = T + V(q) with learned diagonal masses, as the paper "
               "states; the same model families, not the same computation)"
               if a.work2 else ""),
            "JAX 1 thread: taskset -c 0, XLA_FLAGS='--xla_cpu_multi_thread_eigen=false "
            "intra_op_parallelism_threads=1'; JAX 2 threads: taskset -c 0,1; "
            "mcgnode's rollouts: taskset -c 0, its epochs on every CPU",
            "cells: median (min–max over rounds); JAX user/sys: CPU time of one timed epoch or "
            "rollout (getrusage of the process around it; steps/s rows also give its wall); "
            "mcgnode: the figure `bench --json --only <figure>` reports (its own median), and "
            "wall/user/sys of that whole process (setup, data and all its repeats)"]
    rows = []
    out = {"header": head, "rows": []}
    for key, label, _, _, _, steps in items:
        d = res[key]
        def jcell(th):
            xs = d[f"jax{th}"]
            if steps is None or key in ("spring_rollout", "pendulum_rollout"):
                vals, unit = [x["wall"] for x in xs], "s"
            else:
                vals, unit = [steps / x["wall"] for x in xs], "steps/s"
            med = statistics.median
            wall = med(x["wall"] for x in xs)
            cpu = f"wall {secs(wall)}, " if unit == "steps/s" else ""
            cpu += f"user {secs(med(x['user'] for x in xs))}, sys {secs(med(x['sys'] for x in xs))}"
            return vals, unit, f"{fmt_range(vals, unit)}; {cpu}"
        j1, unit, c1 = jcell(1)
        j2, _, c2 = jcell(2)
        for f in MCG[key]:
            ms = d["mcg"][f]
            mv = [m["value"] for m in ms]
            pw = statistics.median(m["process"]["wall"] for m in ms)
            pu = statistics.median(m["process"]["user"] for m in ms)
            ps = statistics.median(m["process"]["sys"] for m in ms)
            mcell = (f"{fmt_range(mv, unit)}; process: wall {secs(pw)}, user {secs(pu)}, "
                     f"sys {secs(ps)}")
            med = statistics.median
            if unit == "steps/s":
                rat = [med(mv) / med(j1), med(mv) / med(j2)]
                rng = [(min(mv) / max(j), max(mv) / min(j)) for j in (j1, j2)]
            else:
                rat = [med(j1) / med(mv), med(j2) / med(mv)]
                rng = [(min(j) / max(mv), max(j) / min(mv)) for j in (j1, j2)]
            ratio = " / ".join(f"{x:.1f}x ({lo:.1f}–{hi:.1f})" for x, (lo, hi) in zip(rat, rng))
            name = label
            if "(candle)" in f:
                name += ", mcgnode candle 1 thread"
            elif "thread" in f:
                threads = re.search(r"(\d+) thread", f).group(1)
                name += f", mcgnode native {threads} thread(s)"
            rows.append([name, c1, c2, mcell, ratio])
            out["rows"].append({"work": name, "jax1": j1, "jax2": j2, "mcgnode": mv,
                                "unit": unit, "ratio_jax1": rat[0], "ratio_jax2": rat[1],
                                "jax1_runs": d["jax1"], "jax2_runs": d["jax2"], "mcgnode_runs": ms})
    print()
    for h in head:
        print(h)
    print()
    print("| work | JAX 1 thread | JAX 2 threads | mcgnode | JAX 1 / 2 threads vs mcgnode |")
    print("| --- | --- | --- | --- | --- |")
    for row in rows:
        print("| " + " | ".join(row) + " |")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(out, fh, indent=1)
        print(f"\nwrote {a.json}")


def main():
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="cmd", required=True)
    q = sub.add_parser("prepare")
    q.add_argument("ref")
    q.add_argument("work")
    q.add_argument("--baselines", nargs=2, metavar=("REF2", "WORK2"))
    q = sub.add_parser("job")
    q.add_argument("work")
    q.add_argument("script")
    q.add_argument("out")
    q.add_argument("--reps", type=int, default=3)
    q.add_argument("--params")
    q.add_argument("--allow-end", action="store_true")
    q = sub.add_parser("harness")
    for o in ["--ref", "--work", "--mcgnode", "--venv-python", "--json", "--lock",
              "--load-before", "--commit-at-start", "--jaxmd", "--ref2", "--work2"]:
        q.add_argument(o)
    q.add_argument("--rounds", type=int, default=3)
    q.add_argument("--quick", action="store_true")
    q.add_argument("--timeout", type=float, default=1800)
    argv = sys.argv[1:]
    cut = argv.index("--") if "--" in argv else len(argv)
    rest = argv[cut + 1:]
    a = p.parse_args(argv[:cut])
    a.rest = rest  # their script's own (fire) arguments, after `--`
    if a.cmd == "prepare":
        prepare(a.ref, a.work, NEEDED, EDITS)
        if a.baselines:
            prepare(a.baselines[0], a.baselines[1], BASELINE_NEEDED, BASELINE_EDITS,
                    BASELINE_DIRS)
        print("shims at import, for every script run (nothing of theirs edited for these):")
        for shim in SHIMS:
            print(f"  {shim}")
    elif a.cmd == "job":
        if a.allow_end:  # data scripts: run to their end
            import builtins
            import runpy
            os.chdir(os.path.join(os.path.abspath(a.work), "scripts"))
            sys.path[:0] = [os.path.join(os.path.abspath(a.work), "scripts"), os.path.abspath(a.work)]
            install_shims(None)
            builtins.__mcgnode_bench__ = None
            sys.argv = [a.script] + a.rest
            runpy.run_path(a.script, run_name="__main__")
        else:
            job(a)
    else:
        res, items, info, rounds = harness(a)
        table(a, res, items, info, rounds)


if __name__ == "__main__":
    main()
