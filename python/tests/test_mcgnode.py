"""The mcgnode Python package against the `mcgnode` command line.

Every check compares with what the CLI does on the same input: bags written
by `mcgnode simulate` (and rewritten as rosbag2 directories by rosbags), read
by `read_bag` and by `mcgnode bag info` / an independent decoder; rollouts by
`Model.rollout` and `mcgnode rollout`, equal bit for bit; error messages equal
to the CLI's; a model trained through `mcgnode.train` and through `mcgnode
train` with the same options, equal but for the wall time.

Run by tests/python.rs (`cargo test --release --test python`), which builds
and installs the wheel and sets MCGNODE_BIN; standalone: build and install
the wheel, then `MCGNODE_BIN=target/release/mcgnode .venv/bin/python3 -m
pytest python/tests`.
"""

import inspect
import json
import os
import re
import shlex
import struct
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import mcgnode

ROOT = Path(__file__).resolve().parents[2]
SPRING_MODEL = ROOT / "bags/models/spring5-mcgnode.json"
PENDULUM_MODEL = ROOT / "bags/models/pendulum5-mcgnode.json"


def mcgnode_bin() -> str:
    b = os.environ.get("MCGNODE_BIN")
    if not b:
        target = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
        b = str(target / "release/mcgnode")
    assert Path(b).exists(), (
        f"the mcgnode binary {b} is missing: build it (cargo build --release) "
        "or set MCGNODE_BIN"
    )
    return b


def cli(*args, ok=True):
    """Runs `mcgnode ARGS` and returns the finished process."""
    p = subprocess.run(
        [mcgnode_bin(), *map(str, args)], capture_output=True, text=True, cwd=ROOT
    )
    if ok:
        assert p.returncode == 0, f"mcgnode {args} failed:\n{p.stderr}"
    else:
        assert p.returncode != 0, f"mcgnode {args} succeeded:\n{p.stdout}"
    return p


def cli_error(*args) -> str:
    """The message `mcgnode ARGS` fails with (after `error: `)."""
    lines = [l for l in cli(*args, ok=False).stderr.splitlines() if l.startswith("error: ")]
    assert lines, f"mcgnode {args} printed no error line"
    return lines[-1][len("error: "):]


def same_bits(a, b) -> bool:
    """Equal shapes and float64 bit patterns (so -0.0 differs from 0.0)."""
    a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
    return (
        a.shape == b.shape
        and a.dtype == b.dtype == np.float64
        and np.array_equal(a.view(np.uint64), b.view(np.uint64))
    )


@pytest.fixture(scope="session")
def bags(tmp_path_factory):
    d = tmp_path_factory.mktemp("bags")
    spring, pendulum = d / "spring.mcap", d / "pendulum.mcap"
    cli("simulate", "--trajectories", 3, "--states", 20, "--seed", 3, "--out", spring)
    cli("simulate", "--system", "pendulum", "--trajectories", 2, "--states", 10,
        "--seed", 4, "--out", pendulum)
    periodic = d / "periodic.mcap"
    cli("simulate", "--system", "periodic-spheres", "--particles", 16, "--trajectories", 1,
        "--states", 5, "--seed", 5, "--out", periodic)
    return {"dir": d, "spring": spring, "pendulum": pendulum, "periodic": periodic}


@pytest.fixture(scope="session")
def gnode(bags):
    """A tiny GNODE trained through Python (it learns little, and says so)."""
    out = bags["dir"] / "gnode.json"
    with pytest.warns(UserWarning, match="explains only"):
        mcgnode.train(bags["spring"], out, variant="gnode", epochs=2, quiet=True)
    return out


# -- read_bag -----------------------------------------------------------------


def test_read_bag_matches_bag_info_and_an_independent_decoder(bags):
    trs = mcgnode.read_bag(bags["spring"])
    info = cli("bag", "info", bags["spring"]).stdout
    m = re.search(r"spring: (\d+) trajectories, (\d+) particles, (\d)D, (\d+) states, "
                  r"longest ([0-9.]+) s", info)
    assert m, info
    assert len(trs) == int(m[1]) == 3
    assert all(t["positions"].shape[1] == int(m[2]) and t["dim"] == int(m[3]) for t in trs)
    assert sum(len(t["stamps"]) for t in trs) == int(m[4])
    assert max(t["stamps"][-1] for t in trs) == pytest.approx(float(m[5]), abs=1e-3)
    assert "field: none" in info
    for t in trs:
        assert t["field"] == {"gravity": 0.0, "drag": 0.0, "force": []}
        assert (t["dt"], t["save_every"]) == (1e-3, 100)
        assert t["velocities_derived"] is False
    # Every message, decoded by the Python mcap readers, bit for bit.
    out = subprocess.run(
        [sys.executable, ROOT / "scripts/decode_bag.py", bags["spring"], "--bits"],
        capture_output=True, text=True, check=True,
    )
    msgs = json.loads(out.stdout)["messages"]
    f = lambda bits: struct.unpack("<d", struct.pack("<Q", bits))[0]
    by_id = {t["id"]: t for t in trs}
    for msg in msgs:
        t, k = by_id[msg["trajectory_id"]], msg["step"]
        q = np.array([[f(p[0]), f(p[1])] for p in msg["positions"]])
        v = np.array([[f(p[0]), f(p[1])] for p in msg["velocities"]])
        assert same_bits(t["positions"][k], q) and same_bits(t["velocities"][k], v)
        assert same_bits(t["masses"], np.array([f(x) for x in msg["masses"]]))
        edges = np.array([[a, b, kind, f(r), f(s)] for a, b, kind, r, s in zip(
            msg["edge_a"], msg["edge_b"], msg["edge_kind"], msg["edge_rest_length"],
            msg["edge_stiffness"])], dtype=np.float64)
        assert same_bits(t["edges"], edges)
    assert len(msgs) == sum(len(t["stamps"]) for t in trs)


def test_read_bag_reads_rosbag2_directories_and_several_paths(bags):
    ref = mcgnode.read_bag(bags["spring"])
    for storage in ["sqlite3", "mcap"]:
        out = bags["dir"] / f"rosbag2_{storage}"
        subprocess.run(
            [sys.executable, ROOT / "scripts/write_rosbag2.py", bags["spring"], out,
             "--storage", storage, "--compression", "message"],
            check=True, capture_output=True,
        )
        got = mcgnode.read_bag(out)
        assert len(got) == len(ref)
        for a, b in zip(got, ref):
            for k in ["positions", "velocities", "stamps", "masses", "edges", "anchors"]:
                assert same_bits(a[k], b[k]), (storage, k)
        # The .db3 file alone, too.
        if storage == "sqlite3":
            (db3,) = out.glob("*.db3")
            assert len(mcgnode.read_bag(db3)) == len(ref)
    # Several paths: their trajectories in order (as `train --data A B`).
    both = mcgnode.read_bag([bags["spring"], bags["dir"] / "rosbag2_sqlite3"])
    assert [t["id"] for t in both] == [0, 1, 2, 0, 1, 2]
    assert same_bits(both[4]["positions"], ref[1]["positions"])


def test_read_bag_gives_the_pendulum_graph_with_anchors(bags):
    t = mcgnode.read_bag(bags["pendulum"])[0]
    n = t["positions"].shape[1]
    assert t["anchors"].shape == (1, 2)
    assert t["field"]["gravity"] == 10.0
    # Bars (kind 1); the first hangs from anchor 0, written b = n + 0.
    assert set(t["edges"][:, 2]) == {1.0}
    assert n in set(t["edges"][:, 1].astype(int))
    assert t["accelerations"].shape == t["positions"].shape


def test_read_bag_gives_contacts_as_bag_info_does(bags):
    spheres = bags["dir"] / "spheres.mcap"
    cli("simulate", "--system", "soft-spheres", "--particles", 12, "--trajectories", 1,
        "--states", 3, "--seed", 5, "--out", spheres)
    info = cli("bag", "info", spheres).stdout
    m = re.search(r"contacts: interaction radius ([0-9.e-]+) .*?(\d+) kinematic particles", info)
    assert m, info
    (t,) = mcgnode.read_bag(spheres)
    assert t["interaction_radius"] == float(m[1]) > 0
    assert t["kinematic"].dtype == np.bool_ and t["kinematic"].shape == (t["masses"].shape[0],)
    assert int(t["kinematic"].sum()) == int(m[2]) > 0
    # Free balls move, the walls do not.
    moved = np.abs(t["positions"][-1] - t["positions"][0]).max(axis=1) > 0
    assert moved[~t["kinematic"]].all() and not moved[t["kinematic"]].any()
    # A bag without contacts: radius 0, nothing kinematic.
    plain = mcgnode.read_bag(bags["spring"])[0]
    assert plain["interaction_radius"] == 0.0 and not plain["kinematic"].any()


# -- rollouts against `mcgnode rollout` --------------------------------------


def cli_rollout(model, bag, trajectory, steps, dt, every, tmp):
    out = tmp / f"cli_rollout_{abs(hash((str(model), str(bag), trajectory, steps, dt, every)))}.mcap"
    cli("rollout", "--model", model, "--initial", bag, "--trajectory", trajectory,
        "--duration", repr(steps * dt), "--dt", repr(dt), "--save-every", every, "--out", out)
    (t,) = mcgnode.read_bag(out)
    return t


@pytest.mark.parametrize("model, bag, steps, dt, every", [
    (SPRING_MODEL, "spring", 300, 1e-3, 1),
    (SPRING_MODEL, "spring", 700, 1e-3, 7),
    ("truth:spring", "spring", 300, 1e-3, 1),
    ("still", "spring", 50, 1e-3, 1),
    (PENDULUM_MODEL, "pendulum", 400, 1e-5, 1),
    ("truth:pendulum", "pendulum", 400, 1e-5, 1),
])
def test_rollout_equals_the_cli_bit_for_bit(bags, tmp_path, model, bag, steps, dt, every):
    tr = mcgnode.read_bag(bags[bag])[1]
    got = mcgnode.load_model(model).rollout(tr, steps, dt, every=every)
    want = cli_rollout(model, bags[bag], tr["id"], steps, dt, every, tmp_path)
    assert got["positions"].shape == (steps // every + 1, *tr["positions"].shape[1:])
    assert same_bits(got["positions"], want["positions"])
    assert same_bits(got["velocities"], want["velocities"])
    assert np.allclose(got["stamps"], want["stamps"], rtol=0, atol=1e-9)


def test_a_periodic_bag_has_its_box_and_rolls_out_wrapped_as_the_cli(bags, tmp_path):
    (tr,) = mcgnode.read_bag(bags["periodic"])
    box = tr["periodic_box"]
    assert box is not None and box["periodic"].all()
    assert mcgnode.read_bag(bags["spring"])[0]["periodic_box"] is None
    model = tmp_path / "periodic-mcgnode.json"  # barely trained: the wrapping is what counts
    cli("train", "--data", bags["periodic"], "--out", model, "--model", "mcgnode",
        "--epochs", 2, "--quiet")
    got = mcgnode.load_model(model).rollout(tr, 400, tr["dt"])
    want = cli_rollout(model, bags["periodic"], tr["id"], 400, tr["dt"], 1, tmp_path)
    assert same_bits(got["positions"], want["positions"])
    q = got["positions"]
    assert ((q >= box["lower"]) & (q < box["upper"])).all(), "wrapped into the box"


def test_a_trained_gnode_rolls_out_as_the_cli_and_its_accelerations_are_the_cli_s(
        bags, gnode, tmp_path):
    tr = mcgnode.read_bag(bags["spring"])[2]
    m = mcgnode.load_model(gnode)
    got = m.rollout(tr, 200, 1e-3)
    want = cli_rollout(gnode, bags["spring"], tr["id"], 200, 1e-3, 1, tmp_path)
    assert same_bits(got["positions"], want["positions"])
    assert same_bits(got["velocities"], want["velocities"])
    # The CLI records the model's acceleration at every state it writes.
    acc = m.accelerations(want["positions"], want["velocities"], tr["masses"], tr["edges"])
    assert same_bits(acc, want["accelerations"])
    one = m.accelerations(want["positions"][5], want["velocities"][5], tr["masses"], tr["edges"])
    assert same_bits(one, want["accelerations"][5])


def test_rollout_defaults_to_the_bag_step_and_arrays_give_the_same(bags):
    tr = mcgnode.read_bag(bags["pendulum"])[0]
    m = mcgnode.load_model(PENDULUM_MODEL)
    by_dict = m.rollout(tr, 300)  # dt: the bag's system_config, 1e-5
    by_arrays = m.rollout_arrays(
        tr["positions"][0], tr["velocities"][0], tr["masses"], tr["edges"], tr["anchors"],
        steps=300, dt=1e-5, types=tr["types"])
    assert same_bits(by_dict["positions"], by_arrays["positions"])
    assert same_bits(by_dict["velocities"], by_arrays["velocities"])
    assert by_dict["stamps"][-1] == pytest.approx(300 * 1e-5)


def test_the_truth_rollout_reproduces_the_simulated_bag(bags):
    tr = mcgnode.read_bag(bags["spring"])[0]
    every = tr["save_every"]
    out = mcgnode.load_model("truth:spring").rollout(tr, (len(tr["stamps"]) - 1) * every,
                                                    every=every)
    assert same_bits(out["positions"], tr["positions"])


def test_contact_models_roll_out_as_the_cli_and_kinematic_motion_is_followed(bags, tmp_path):
    # A model trained on soft spheres (contacts within radius 1, walls
    # kinematic) rolls out from Python as from the CLI, walls held.
    spheres = tmp_path / "box.mcap"
    cli("simulate", "--system", "soft-spheres", "--particles", 9, "--trajectories", 2,
        "--states", 6, "--out", spheres)
    model = tmp_path / "contact.json"
    cli("train", "--model", "mcgnode", "--data", spheres, "--epochs", 3, "--out", model)
    tr = mcgnode.read_bag(spheres)[0]
    m = mcgnode.load_model(model)
    got = m.rollout(tr, 200, 1e-3)
    want = cli_rollout(model, spheres, tr["id"], 200, 1e-3, 1, tmp_path)
    assert same_bits(got["positions"], want["positions"])
    walls = tr["kinematic"]
    assert (got["positions"][-1][walls] == tr["positions"][0][walls]).all()
    # The held chain's gripper moved along given positions: exactly there,
    # and the chain answers (it ends elsewhere than with the gripper held).
    held = tmp_path / "held.mcap"
    cli("simulate", "--system", "held-chain", "--particles", 4, "--trajectories", 1,
        "--states", 2, "--out", held)
    (h,) = mcgnode.read_bag(held)
    truth = mcgnode.load_model("truth:held-chain")
    steps, dt = 400, 1e-3
    t = np.arange(steps + 1) * dt
    path = np.stack([0.3 * (1 - np.cos(2 * t)), 0.1 * np.sin(3 * t)], axis=1)[:, None, :]
    moved = truth.rollout(h, steps, dt, kinematic_positions=path)
    still = truth.rollout(h, steps, dt)
    g = np.flatnonzero(h["kinematic"])
    assert g.tolist() == [4]
    assert same_bits(moved["positions"][:, g, :], path)
    assert np.abs(moved["positions"][-1, :4] - still["positions"][-1, :4]).max() > 1e-3
    arrays = truth.rollout_arrays(
        h["positions"][0], h["velocities"][0], h["masses"], h["edges"], steps=steps, dt=dt,
        types=h["types"], kinematic=h["kinematic"], kinematic_positions=path)
    assert same_bits(arrays["positions"], moved["positions"])
    with pytest.raises(ValueError, match=r"kinematic_positions must have shape \(steps \+ 1"):
        truth.rollout(h, steps, dt, kinematic_positions=path[:-1])


# -- forces -----------------------------------------------------------------


def test_forces_of_mcgnode_and_truth_and_refused_for_gnode(bags, gnode):
    tr = mcgnode.read_bag(bags["spring"])[0]
    args = (tr["positions"][3], tr["velocities"][3], tr["masses"], tr["edges"])
    f = mcgnode.load_model(SPRING_MODEL).forces(*args)
    n = tr["positions"].shape[1]
    assert f["total"].shape == (n, 2) and f["pair_forces"].shape[1] == 2
    assert f["pairs"].shape == (f["pair_forces"].shape[0], 2) and f["pairs"].dtype == np.int64

    def summed(f):
        """Each pair's force on a, and its opposite on b, summed per particle."""
        s = np.zeros((n, 2))
        np.add.at(s, f["pairs"][:, 0], f["pair_forces"])
        np.add.at(s, f["pairs"][:, 1], -f["pair_forces"])
        return s

    # MCGNODE's totals are its pairwise forces summed (closed system: no body force).
    assert np.allclose(summed(f), f["total"], rtol=1e-12, atol=1e-12)
    truth = mcgnode.load_model("truth:spring")
    ft = truth.forces(*args)
    assert np.allclose(ft["total"], truth.accelerations(*args) * tr["masses"][:, None],
                       rtol=1e-12, atol=1e-12)
    assert ft["pairs"].shape == (len(tr["edges"]), 2)
    assert np.allclose(summed(ft), ft["total"], rtol=1e-12, atol=1e-12)
    still = mcgnode.load_model("still").forces(*args)
    assert not still["total"].any() and still["pairs"].shape == (0, 2)
    g = mcgnode.load_model(gnode)
    assert not g.predicts_forces
    with pytest.raises(mcgnode.Error, match="predicts accelerations, not forces"):
        g.forces(*args)


# -- errors: the CLI's messages ---------------------------------------------


def test_errors_carry_the_cli_messages(bags, tmp_path):
    out = tmp_path / "o.mcap"
    for ref in ["missing-model.json", "truth:rope"]:
        with pytest.raises(mcgnode.Error) as e:
            mcgnode.load_model(ref)
        assert str(e.value) == cli_error("rollout", "--model", ref, "--out", out)
    not_a_bag = ROOT / "README.md"
    with pytest.raises(mcgnode.Error) as e:
        mcgnode.read_bag(not_a_bag)
    assert str(e.value) == cli_error("train", "--model", "mcgnode", "--data", not_a_bag,
                                     "--out", tmp_path / "m.json")
    assert cli_error("rollout", "--model", "still", "--initial", not_a_bag,
                     "--out", out) == f"reading --initial: {e.value}"
    # A spring model refuses a pendulum's bars and anchors, in the CLI's words.
    tr = mcgnode.read_bag(bags["pendulum"])[0]
    with pytest.raises(mcgnode.Error) as e:
        mcgnode.load_model(SPRING_MODEL).rollout(tr, 10)
    assert str(e.value) == cli_error("rollout", "--model", SPRING_MODEL, "--initial",
                                     bags["pendulum"], "--out", out)
    # A bad variant: named, with the reason the CLI gives for `--model`.
    with pytest.raises(ValueError) as e:
        mcgnode.train(bags["spring"], tmp_path / "m.json", variant="rope")
    prefix = "train() argument 'variant': "
    assert str(e.value).startswith(prefix)
    assert str(e.value)[len(prefix):] in cli_error(
        "train", "--model", "rope", "--data", bags["spring"], "--out", tmp_path / "m.json")
    with pytest.raises(TypeError, match="unexpected keyword argument 'epoch'"):
        mcgnode.train(bags["spring"], tmp_path / "m.json", variant="gnode", epoch=3)
    with pytest.raises(ValueError, match="positions must have shape"):
        mcgnode.load_model("still").rollout_arrays(np.zeros(3), np.zeros(3), [1.0], [],
                                                   steps=1, dt=0.1)


def test_a_start_out_of_range_warns_as_the_cli(bags):
    tr = mcgnode.read_bag(bags["spring"])[0]
    fast = dict(tr, velocities=tr["velocities"] * 1e6)
    with pytest.warns(RuntimeWarning, match="out of the model's training range"):
        out = mcgnode.load_model(SPRING_MODEL).rollout(fast, 0)
    assert out["positions"].shape == (1, 5, 2)


# -- training against `mcgnode train` ----------------------------------------


def test_train_equals_the_cli_with_the_same_options(bags, tmp_path):
    py_out, cli_out = tmp_path / "py.json", tmp_path / "cli.json"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # a tiny model learns little
        report = mcgnode.train(
            bags["spring"], py_out, variant="mcgnode", epochs=4, seed=5,
            lr_drop=[(2, 1e-3)], block_hidden={"edge_out": [4, 4]}, edge_physics=True,
            quiet=True,
        )
    cli("train", "--model", "mcgnode", "--data", bags["spring"], "--out", cli_out,
        "--epochs", 4, "--seed", 5, "--lr-drop", "2:1e-3", "--block-hidden", "edge_out=4,4",
        "--edge-physics", "--quiet")
    a, b = json.loads(py_out.read_text()), json.loads(cli_out.read_text())
    for f in (a, b):
        f["training"].pop("seconds")
    assert a == b
    got = {k: v for k, v in report.items() if k not in ("seconds", "out", "summary",
                                                       "explained_line")}
    assert got == a["training"]
    assert report["epochs_run"] == 4 and report["lr_drops"] == [[2, 1e-3]]
    assert report["out"] == str(py_out)
    assert report["summary"].startswith(f"wrote {py_out}: 4 epochs")
    # The paper's recipe, one keyword away as it is one flag away.
    py_out, cli_out = tmp_path / "py-paper.json", tmp_path / "cli-paper.json"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        mcgnode.train(bags["spring"], py_out, variant="gnode", recipe="paper", epochs=2,
                      hidden=3, lr_drop="1:1e-4", quiet=True)
    cli("train", "--model", "gnode", "--data", bags["spring"], "--out", cli_out,
        "--recipe", "paper", "--epochs", 2, "--hidden", 3, "--lr-drop", "1:1e-4", "--quiet")
    a, b = json.loads(py_out.read_text()), json.loads(cli_out.read_text())
    for f in (a, b):
        f["training"].pop("seconds")
    assert a == b
    assert a["training"]["batch"] == 100 and a["hyper"]["hidden"] == 3


def test_train_takes_the_cli_s_options_and_names_a_bad_one(bags, tmp_path):
    # Every `mcgnode train` option is a keyword (dashes as underscores), and
    # the stubs' TrainOptions lists the same.
    help_text = cli("train", "--help").stdout
    flags = set(re.findall(r"^\s+(?:-\w, )?--([a-z][a-z-]*)", help_text, re.M))
    flags = {f.replace("-", "_") for f in flags} - {"model", "data", "out", "help"}
    assert set(mcgnode._mcgnode._TRAIN_OPTIONS) == flags
    stub = (Path(mcgnode.__file__).parent / "__init__.pyi").read_text()
    block = re.search(r"^class TrainOptions\(TypedDict, total=False\):\n(.*?)\n\n", stub,
                      re.M | re.S)
    assert set(re.findall(r"^    (\w+):", block[1], re.M)) == flags
    # A bad value is a ValueError naming its keyword, raised before training.
    out = tmp_path / "never.json"
    for kw, match in [
        ({"epochs": "many"}, "'epochs'"),
        ({"recipe": "fast"}, "'recipe': \"fast\" is not one of auto, paper"),
        ({"engine": "gpu"}, "'engine'"),
        ({"lr_drop": [(2, -1.0)]}, "'lr_drop': the learning rate after epoch 2"),
        ({"lr_drop": "2-1e-3"}, "'lr_drop': expected EPOCH:LR"),
        ({"block_hidden": {"edge_out": [16, 0]}}, "'block_hidden'"),
        ({"checkpoint_every": 5.0}, "'checkpoint_every': needs checkpoint="),
    ]:
        with pytest.raises(ValueError, match=match):
            mcgnode.train(bags["spring"], out, variant="gnode", **kw)
    assert not out.exists()


# -- the README's example and the type stubs --------------------------------


def test_the_readme_example_runs_as_the_readme_shows():
    readme = (ROOT / "README.md").read_text()
    (line,) = [l.strip() for l in readme.splitlines()
               if "python/examples/compare.py" in l and l.strip().startswith(".venv/")]
    script = (ROOT / "python/examples/compare.py").read_text()
    assert len(script.splitlines()) <= 10
    assert script in readme, "the README shows python/examples/compare.py as it is"
    words = shlex.split(line)
    p = subprocess.run(words, capture_output=True, text=True,
                       cwd=ROOT, check=True)
    mse = dict(l.rsplit(": position MSE ", 1) for l in p.stdout.splitlines())
    mse = {k: float(v) for k, v in mse.items()}
    assert list(mse) == words[3:], p.stdout
    assert mse["truth:spring"] == 0.0
    assert mse["bags/models/spring5-mcgnode.json"] < mse["still"] / 100


def stub_params(sig: str):
    """The parameter names of a stub's signature text (commas inside [] kept)."""
    names, depth, cur = [], 0, ""
    for c in sig + ",":
        depth += c in "[(" and 1 or 0
        depth -= c in "])" and 1 or 0
        if c == "," and depth == 0:
            name = cur.split(":")[0].split("=")[0].strip().lstrip("*")
            if name:
                names.append(name)
            cur = ""
        else:
            cur += c
    return names


def test_the_stubs_name_what_the_module_has():
    stub = (Path(mcgnode.__file__).parent / "__init__.pyi").read_text()
    assert (Path(mcgnode.__file__).parent / "py.typed").exists()
    for name in mcgnode.__all__:
        assert hasattr(mcgnode, name)
        assert re.search(rf"^(def|class) {name}\b|^{name}:", stub, re.M), name
    for fn in [mcgnode.read_bag, mcgnode.load_model, mcgnode.train]:
        params = list(inspect.signature(fn).parameters)
        m = re.search(rf"^def {fn.__name__}\((.*?)\) ->", stub, re.M | re.S)
        assert stub_params(m[1]) == params, fn.__name__
    for meth in ["rollout", "rollout_arrays", "accelerations", "forces"]:
        params = list(inspect.signature(getattr(mcgnode.Model, meth)).parameters)
        m = re.search(rf"    def {meth}\((.*?)\) ->", stub, re.S)
        assert stub_params(m[1]) == params, meth
    assert mcgnode.read_bag.__doc__ and mcgnode.Model.rollout.__doc__


def test_train_ensemble_writes_its_members_as_the_cli_does(bags, tmp_path):
    # ensemble=K goes the CLI's way (one file, K - 1 members beside its own
    # weights); out of 1..64 it is a ValueError naming it.
    py_out, cli_out = tmp_path / "py.json", tmp_path / "cli.json"
    with pytest.warns(UserWarning):
        mcgnode.train(bags["spring"], py_out, variant="mcgnode", epochs=2, ensemble=3,
                      quiet=True)
    cli("train", "--data", bags["spring"], "--out", cli_out, "--model", "mcgnode",
        "--epochs", 2, "--ensemble", 3, "--quiet")
    py, via_cli = (json.loads(p.read_text()) for p in (py_out, cli_out))
    assert len(py["members"]) == len(via_cli["members"]) == 2
    assert py["members"][0]["weights"] == via_cli["members"][0]["weights"]
    with pytest.raises(ValueError, match="ensemble"):
        mcgnode.train(bags["spring"], py_out, variant="mcgnode", ensemble=0, quiet=True)
    # Its rollout is the members' mean with their spread, each member rolled
    # out alone as a single-model file (numpy's mean and deviation, not ours).
    ens = mcgnode.load_model(cli_out)
    assert ens.members == 3 and mcgnode.load_model(SPRING_MODEL).members == 1
    tr = mcgnode.read_bag(bags["spring"])[0]
    got = ens.rollout(tr, 100, 1e-3)
    alone = []
    for k, member in enumerate([None, *via_cli["members"]]):
        one = dict(via_cli, members=[])
        if member is not None:
            one.update(weights=member["weights"], training=member["training"], optimizer=None)
        path = tmp_path / f"member{k}.json"
        path.write_text(json.dumps(one))
        alone.append(mcgnode.load_model(path).rollout(tr, 100, 1e-3)["positions"])
    alone = np.stack(alone)
    assert np.allclose(got["positions"], alone.mean(axis=0), rtol=0, atol=1e-12)
    want = np.sqrt(alone.var(axis=0).mean(axis=-1))
    assert got["spread"].shape == want.shape == got["positions"].shape[:2]
    assert np.allclose(got["spread"], want, rtol=0, atol=1e-12)
    # The start is common (rounding of the mean only); the members then part.
    assert got["spread"][0].max() < 1e-12 and (got["spread"][-1] > 1e-9).all()
    assert "spread" not in mcgnode.load_model(SPRING_MODEL).rollout(tr, 10, 1e-3)
