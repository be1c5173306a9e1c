//! Hostile bytes (issue 20): mutated MCAP files, CDR messages, model files
//! and GNS TFRecord files with their metadata
//! go through the real readers. Every case must return (never panic), within
//! a time bound (never hang), and every refusal must say something.
//!
//! Inputs start from small valid files the library writes itself and take a
//! few mutations: bit flips, overwrites, interesting integers (lengths,
//! counts, NaN bit patterns) at random offsets, truncation, inserted, deleted
//! and duplicated runs; for bags also valid containers around mutated
//! messages; for model files also JSON edits (numbers replaced by huge,
//! negative or non-finite ones, keys deleted, arrays shortened or grown,
//! values of the wrong type). The RNG is seeded, so a run is reproducible;
//! `PROPTEST_RNG_SEED=<u64>` runs another set of cases, and
//! `MCGNODE_FUZZ_SCALE=<factor>` scales every case count (a longer soak, or a
//! quick look).

// A test is one scenario read top to bottom; splitting it would hide the
// order its checks depend on.
#![allow(clippy::too_many_lines)]

use std::collections::BTreeMap;
use std::io::Cursor;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use mcap::records::{MessageHeader, Metadata};
use mcgnode::baselines::{BaselineFile, BaselineHyper, BaselineNet, Kind};
use mcgnode::data::import::{encode_record, gns_trajectories, GnsMetadata};
use mcgnode::data::msg::{encode_cdr, particle_state_schema, Layout, ParticleStateV1};
use mcgnode::data::msg::{PARTICLE_STATE_MSG_V1, PARTICLE_STATE_TYPE};
use mcgnode::data::{read_trajectories, ParticleState, METADATA_NAME, PARTICLE_STATE_TOPIC};
use mcgnode::gnode::{ArchPreset, ModelFile, Net, Norm, Variant};
use mcgnode::models::{load_any_model, ModelRef};
use mcgnode::physics::{Field, SystemConfig, SystemKind};
use mcgnode::system::{Graph, State, Trajectory};
use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::{Config, RngSeed, TestCaseError, TestCaseResult, TestRunner};
use rand::SeedableRng;

/// Cases per property: MCAP 30,000 + 15,000, CDR 100,000, model files
/// 20,000 + 10,000; 175,000 in all (issue 20 asks for 100,000), about 15 s
/// on two cores; GNS TFRecord files and metadata 20,000 + 5,000 on top.
const MCAP_BYTE_CASES: u32 = 30_000;
const MCAP_MESSAGE_CASES: u32 = 15_000;
const CDR_CASES: u32 = 100_000;
const MODEL_CASES: u32 = 20_000;
const BASELINE_CASES: u32 = 10_000;
/// GNS TFRecord files: mutated file bytes, and mutated records framed anew
/// (so that the protobuf decoder, not the CRC, meets them), and metadata.
const GNS_CASES: u32 = 20_000;
const GNS_METADATA_CASES: u32 = 5_000;

/// A single case taking longer than this twice in a row fails its property:
/// the readers take about a millisecond at most on these small inputs, so
/// seconds mean a pathological loop or allocation.
const CASE_LIMIT: Duration = Duration::from_secs(2);
/// A case still running after this is a hang: the watchdog names it and
/// aborts the test binary (a hung call cannot be failed from inside).
const HANG_LIMIT: Duration = Duration::from_secs(30);

/// The RNG seed: `PROPTEST_RNG_SEED` if set, else a fixed one.
fn seed() -> RngSeed {
    match Config::default().rng_seed {
        RngSeed::Random => RngSeed::Fixed(20),
        fixed @ RngSeed::Fixed(_) => fixed,
    }
}

// ---------------------------------------------------------------- mutations

/// One edit of a byte string.
#[derive(Clone, Debug)]
enum Mutation {
    /// Flip bit `bit` of one byte.
    Flip(Index, u8),
    /// Overwrite bytes from an offset (clipped at the end).
    Overwrite(Index, Vec<u8>),
    /// Write a little-endian integer of `width` bytes (1, 2, 4 or 8) at an
    /// offset: lengths, counts, sizes and float bit patterns live there.
    Int(Index, usize, u64),
    /// Cut the input at a length.
    Truncate(Index),
    /// Insert bytes at an offset.
    Insert(Index, Vec<u8>),
    /// Delete a run of bytes.
    Delete(Index, usize),
    /// Copy a run of the input and insert it elsewhere.
    Splice { from: Index, len: usize, to: Index },
}

/// Integers that tend to matter to a parser: boundaries of each width, small
/// counts, and the bit patterns of NaN, infinities and huge floats.
fn interesting_int() -> impl Strategy<Value = u64> {
    prop_oneof![
        prop::sample::select(vec![
            0,
            1,
            2,
            3,
            4,
            7,
            8,
            0x7f,
            0x80,
            0xff,
            0x100,
            0x7fff,
            0xffff,
            0x1_0000,
            0x7fff_ffff,
            0x8000_0000,
            0xffff_ffff,
            0x1_0000_0000,
            0x7fff_ffff_ffff_ffff,
            u64::MAX,
            f64::NAN.to_bits(),
            f64::INFINITY.to_bits(),
            f64::NEG_INFINITY.to_bits(),
            f64::MAX.to_bits(),
            (-1.0f64).to_bits(),
            1e300f64.to_bits(),
            5e-324f64.to_bits(),
        ]),
        any::<u64>(),
    ]
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let bytes = prop::collection::vec(any::<u8>(), 1..16);
    prop_oneof![
        3 => (any::<Index>(), 0u8..8).prop_map(|(i, b)| Mutation::Flip(i, b)),
        2 => (any::<Index>(), bytes.clone()).prop_map(|(i, b)| Mutation::Overwrite(i, b)),
        3 => (any::<Index>(), prop::sample::select(vec![1usize, 2, 4, 8]), interesting_int())
            .prop_map(|(i, w, v)| Mutation::Int(i, w, v)),
        1 => any::<Index>().prop_map(Mutation::Truncate),
        1 => (any::<Index>(), bytes).prop_map(|(i, b)| Mutation::Insert(i, b)),
        1 => (any::<Index>(), prop_oneof![1usize..16, 1usize..1024])
            .prop_map(|(i, n)| Mutation::Delete(i, n)),
        1 => (any::<Index>(), 1usize..256, any::<Index>())
            .prop_map(|(from, len, to)| Mutation::Splice { from, len, to }),
    ]
}

/// One to four mutations.
fn mutations() -> impl Strategy<Value = Vec<Mutation>> {
    prop::collection::vec(mutation(), 1..=4)
}

/// Applies a mutation (those that need a byte to act on skip an empty input).
fn mutate(data: &mut Vec<u8>, m: &Mutation) {
    let len = data.len();
    match m {
        Mutation::Insert(i, b) => {
            let at = i.index(len + 1);
            data.splice(at..at, b.iter().copied());
        }
        _ if len == 0 => {}
        Mutation::Flip(i, bit) => data[i.index(len)] ^= 1 << bit,
        Mutation::Overwrite(i, b) => {
            let at = i.index(len);
            for (d, s) in data[at..].iter_mut().zip(b) {
                *d = *s;
            }
        }
        Mutation::Int(i, width, v) => {
            let at = i.index(len);
            for (d, s) in data[at..].iter_mut().zip(&v.to_le_bytes()[..*width]) {
                *d = *s;
            }
        }
        Mutation::Truncate(i) => data.truncate(i.index(len)),
        Mutation::Delete(i, n) => {
            let at = i.index(len);
            data.drain(at..(at + n).min(len));
        }
        Mutation::Splice { from, len: n, to } => {
            let at = from.index(len);
            let chunk = data[at..(at + n).min(len)].to_vec();
            let to = to.index(len + 1);
            data.splice(to..to, chunk);
        }
    }
}

fn mutated(seed: &[u8], muts: &[Mutation]) -> Vec<u8> {
    let mut data = seed.to_vec();
    for m in muts {
        mutate(&mut data, m);
    }
    data
}

// ------------------------------------------------------- running one case

/// What a reader made of an input.
enum Outcome {
    /// It read it (and, for model files, ran it).
    Accepted,
    /// It refused it with this message.
    Rejected(String),
}

/// A refusal, checked to say something (an empty message helps nobody).
fn rejected(e: &dyn std::fmt::Display) -> Outcome {
    Outcome::Rejected(e.to_string())
}

/// Counts and guards the cases of one property.
struct Guard {
    name: &'static str,
    accepted: AtomicUsize,
    rejected: AtomicUsize,
    /// The running case: when it started and what it is.
    current: Arc<Mutex<Option<(Instant, String)>>>,
    done: Arc<AtomicBool>,
}

impl Guard {
    /// Starts the watchdog that aborts on a hung case.
    fn new(name: &'static str) -> Self {
        let current: Arc<Mutex<Option<(Instant, String)>>> = Arc::default();
        let done = Arc::new(AtomicBool::new(false));
        let (c, d) = (current.clone(), done.clone());
        std::thread::spawn(move || {
            while !d.load(Ordering::Relaxed) {
                std::thread::sleep(Duration::from_millis(200));
                if let Some((t, what)) = c
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .as_ref()
                {
                    if t.elapsed() > HANG_LIMIT {
                        say(&format!("{name}: case hangs (> {HANG_LIMIT:?}): {what}"));
                        std::process::abort();
                    }
                }
            }
        });
        Self {
            name,
            accepted: AtomicUsize::new(0),
            rejected: AtomicUsize::new(0),
            current,
            done,
        }
    }

    /// Runs one case: no panic, within [`CASE_LIMIT`], a refusal with a message.
    fn case(&self, what: impl Fn() -> String, f: impl Fn() -> Outcome) -> TestCaseResult {
        let timed = || {
            let start = Instant::now();
            *self
                .current
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner) = Some((start, what()));
            let r = catch_unwind(AssertUnwindSafe(&f));
            *self
                .current
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner) = None;
            (r, start.elapsed())
        };
        let (mut r, mut took) = timed();
        if r.is_ok() && took > CASE_LIMIT {
            // A pathological input is slow every time; a stall of the
            // machine (disk, scheduler) is not.
            (r, took) = timed();
        }
        let outcome = r.map_err(|p| {
            let msg = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| (*s).to_string()))
                .unwrap_or_default();
            TestCaseError::fail(format!("{}: panicked ({msg}) on {}", self.name, what()))
        })?;
        if took > CASE_LIMIT {
            return Err(TestCaseError::fail(format!(
                "{}: took {took:?} (> {CASE_LIMIT:?}) on {}",
                self.name,
                what()
            )));
        }
        match outcome {
            Outcome::Accepted => {
                self.accepted.fetch_add(1, Ordering::Relaxed);
            }
            Outcome::Rejected(msg) if msg.trim().is_empty() => {
                return Err(TestCaseError::fail(format!(
                    "{}: an error without a message on {}",
                    self.name,
                    what()
                )))
            }
            Outcome::Rejected(_) => {
                self.rejected.fetch_add(1, Ordering::Relaxed);
            }
        }
        Ok(())
    }
}

/// Runs a property over `cases` inputs and reports the counts.
fn run<S: Strategy>(
    name: &'static str,
    cases: u32,
    strategy: S,
    test: impl Fn(&Guard, S::Value) -> TestCaseResult,
) {
    let scale: f64 = std::env::var("MCGNODE_FUZZ_SCALE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.0);
    let cases = ((f64::from(cases) * scale).round() as u32).max(1);
    let guard = Guard::new(name);
    let seed = seed();
    let mut runner = TestRunner::new(Config {
        cases,
        rng_seed: seed,
        failure_persistence: None,
        // A failure shrinks a little, so that the report comes soon.
        max_shrink_iters: 500,
        ..Config::default()
    });
    let start = Instant::now();
    let result = runner.run(&strategy, |v| test(&guard, v));
    guard.done.store(true, Ordering::Relaxed);
    let (a, r) = (
        guard.accepted.load(Ordering::Relaxed),
        guard.rejected.load(Ordering::Relaxed),
    );
    if let Err(e) = result {
        panic!("{name}: {e}");
    }
    assert!(
        a + r >= cases as usize,
        "{name}: ran {} of {cases} cases",
        a + r
    );
    say(&format!(
        "{name}: {} cases in {:.1} s (seed {seed}): {r} rejected with an error, {a} accepted, 0 panics, 0 hangs",
        a + r,
        start.elapsed().as_secs_f64()
    ));
}

/// Writes a line to stderr past the test harness's capture, so that a
/// passing run shows its counts (and an abort its reason).
fn say(line: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr().lock(), "{line}");
}

// ---------------------------------------------------------------- seeds

/// A short simulated trajectory set of `kind` (small: every case reads it).
fn simulated(kind: SystemKind, particles: usize, field: Option<&Field>) -> Vec<Trajectory> {
    let mut cfg = SystemConfig::new(kind, particles);
    cfg.states = 3;
    if let Some(f) = field {
        cfg.field = f.clone();
    }
    cfg.simulate(2, 7)
}

fn gravity() -> Field {
    Field {
        gravity: 10.0,
        drag: 0.1,
        force: vec![],
    }
}

/// The ParticleState messages `write_trajectories_with_field` writes.
fn messages(trs: &[Trajectory], field: Option<&Field>) -> Vec<ParticleState> {
    trs.iter()
        .flat_map(|tr| {
            tr.samples.iter().enumerate().map(move |(k, s)| {
                ParticleState::from_sample(tr.id, k as u32, &tr.system, &tr.graph, s)
                    .with_field(field)
            })
        })
        .collect()
}

/// A bag as the mcap crate writes it with other options than
/// [`mcgnode::data::BagWriter`]'s (no CRCs, so mutated bytes get past the
/// checksums into the record parsers, decompressors and CDR).
fn raw_bag(opts: mcap::WriteOptions, msgs: &[(String, u64, Vec<u8>)], schema: &str) -> Vec<u8> {
    let mut w = opts
        .profile("ros2")
        .create(Cursor::new(Vec::new()))
        .expect("mcap writer");
    let meta = BTreeMap::from([("system".to_string(), "spring".to_string())]);
    w.write_metadata(&Metadata {
        name: METADATA_NAME.into(),
        metadata: meta,
    })
    .expect("metadata");
    let sid = w
        .add_schema(PARTICLE_STATE_TYPE, "ros2msg", schema.as_bytes())
        .expect("schema");
    let mut channels = BTreeMap::new();
    for (seq, (topic, t, cdr)) in msgs.iter().enumerate() {
        let ch = *channels.entry(topic.clone()).or_insert_with(|| {
            w.add_channel(sid, topic, "cdr", &BTreeMap::new())
                .expect("channel")
        });
        let header = MessageHeader {
            channel_id: ch,
            sequence: seq as u32,
            log_time: *t,
            publish_time: *t,
        };
        w.write_to_known_channel(&header, cdr).expect("message");
    }
    w.finish().expect("finish");
    w.into_inner().into_inner()
}

fn no_crcs() -> mcap::WriteOptions {
    mcap::WriteOptions::new()
        .calculate_chunk_crcs(false)
        .calculate_data_section_crc(false)
        .calculate_summary_section_crc(false)
}

/// The message in the first layout (without the field entries).
fn first_layout(m: &ParticleState) -> ParticleStateV1 {
    ParticleStateV1 {
        header: m.header.clone(),
        trajectory_id: m.trajectory_id,
        step: m.step,
        system: m.system.clone(),
        dimension: m.dimension,
        types: m.types.clone(),
        masses: m.masses.clone(),
        positions: m.positions.clone(),
        velocities: m.velocities.clone(),
        accelerations: m.accelerations.clone(),
        edge_a: m.edge_a.clone(),
        edge_b: m.edge_b.clone(),
        edge_kind: m.edge_kind.clone(),
        edge_rest_length: m.edge_rest_length.clone(),
        edge_stiffness: m.edge_stiffness.clone(),
        anchors: m.anchors.clone(),
    }
}

/// (topic, log time, CDR) of each message, in this build's layout or (`v1`)
/// the first one.
fn encoded(msgs: &[ParticleState], v1: bool) -> Vec<(String, u64, Vec<u8>)> {
    msgs.iter()
        .map(|m| {
            let t = u64::try_from(m.header.stamp.as_nanos()).unwrap_or(0);
            let cdr = if v1 {
                encode_cdr(&first_layout(m))
            } else {
                m.to_cdr()
            };
            (PARTICLE_STATE_TOPIC.to_string(), t, cdr.expect("cdr"))
        })
        .collect()
}

struct Seeds {
    /// Whole bags: (what, bytes).
    bags: Vec<(&'static str, Vec<u8>)>,
    /// Messages of one valid bag, for [`mcap_messages`]: (what, messages).
    bag_messages: Vec<(&'static str, Vec<ParticleState>)>,
    /// CDR messages: (what, layout to decode as, bytes).
    cdr: Vec<(&'static str, Layout, Vec<u8>)>,
    /// Model files: (what, JSON text, a graph and state to run a loaded model on).
    models: Vec<(&'static str, String, Graph, State)>,
    /// Baseline files, likewise.
    baselines: Vec<(&'static str, String, Graph, State)>,
}

fn seeds() -> &'static Seeds {
    static SEEDS: OnceLock<Seeds> = OnceLock::new();
    SEEDS.get_or_init(make_seeds)
}

fn make_seeds() -> Seeds {
    let dir = tempfile::tempdir().expect("tempdir");
    let springs = simulated(SystemKind::Spring, 3, None);
    let field = gravity();
    let pendulum = simulated(SystemKind::Pendulum, 2, Some(&field));
    let meta = BTreeMap::from([("system".to_string(), "spring".to_string())]);

    let written = |name: &str, trs: &[Trajectory], f: Option<&Field>| {
        let p = dir.path().join(name);
        mcgnode::data::write_trajectories_with_field(&p, trs, &meta, f).expect("write bag");
        let bytes = std::fs::read(&p).expect("read bag");
        // The seed itself is a valid bag.
        read_trajectories(&p).expect("seed bag reads");
        bytes
    };
    let spring_msgs = messages(&springs, None);
    let pendulum_msgs = messages(&pendulum, Some(&field));
    let schema = particle_state_schema();
    let bags = vec![
        ("spring bag", written("spring.mcap", &springs, None)),
        (
            "pendulum bag with a field",
            written("pendulum.mcap", &pendulum, Some(&field)),
        ),
        (
            "uncompressed spring bag without CRCs",
            raw_bag(
                no_crcs().compression(None),
                &encoded(&spring_msgs, false),
                &schema,
            ),
        ),
        (
            "zstd pendulum bag without CRCs",
            raw_bag(
                no_crcs().compression(Some(mcap::Compression::Zstd)),
                &encoded(&pendulum_msgs, false),
                &schema,
            ),
        ),
        (
            "lz4 spring bag without CRCs",
            raw_bag(
                no_crcs().compression(Some(mcap::Compression::Lz4)),
                &encoded(&spring_msgs, false),
                &schema,
            ),
        ),
        (
            "unchunked pendulum bag without CRCs",
            raw_bag(
                no_crcs().use_chunks(false),
                &encoded(&pendulum_msgs, false),
                &schema,
            ),
        ),
    ];
    for (what, b) in &bags[2..] {
        let p = dir.path().join("check.mcap");
        std::fs::write(&p, b).expect("write");
        read_trajectories(&p).unwrap_or_else(|e| panic!("seed {what} does not read: {e}"));
    }

    let v1 = encode_cdr(&first_layout(&spring_msgs[1])).expect("v1 cdr");
    let cdr = vec![
        (
            "spring message",
            Layout::Current,
            spring_msgs[0].to_cdr().expect("cdr"),
        ),
        (
            "pendulum message with a field",
            Layout::Current,
            pendulum_msgs[2].to_cdr().expect("cdr"),
        ),
        ("first-layout message", Layout::V1, v1.clone()),
        ("message of unknown layout", Layout::Unknown, v1),
    ];
    for (what, layout, b) in &cdr {
        ParticleState::from_cdr_as(b, *layout)
            .and_then(|m| m.to_parts())
            .unwrap_or_else(|e| panic!("seed {what} does not decode: {e}"));
    }

    let first = |trs: &[Trajectory]| (trs[0].graph.clone(), trs[0].samples[0].state.clone());
    let (sg, ss) = first(&springs);
    let (pg, ps) = first(&pendulum);
    // Small networks: quick to parse and build, and the settings are a
    // larger share of what a JSON edit hits.
    let model_json = |variant: Variant, g: &Graph, paper: bool, norm: bool| {
        let (_, m) = mcgnode::testing::random_model(variant, g, 3).expect("model");
        let mut file = m.file;
        let h = &mut file.hyper;
        (h.hidden, h.embed, h.node_hidden, h.node_layers) = (3, 3, 4, 1);
        if paper {
            *h = h.clone().with_preset(ArchPreset::Paper);
        }
        if norm {
            let mut n = Norm::identity(g.dim);
            n.q_mean = vec![0.25; g.dim];
            n.q_scale = 2.0;
            h.norm = Some(n);
        }
        let net = Net::new(
            file.hyper.clone(),
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(5),
        )
        .expect("net");
        file.weights = net.store.weights().expect("weights");
        let p = dir.path().join("model.json");
        file.save(&p).expect("save model");
        std::fs::read_to_string(&p).expect("read model")
    };
    let models = vec![
        (
            "mcgnode spring model",
            model_json(Variant::Mcgnode, &sg, false, false),
            sg.clone(),
            ss.clone(),
        ),
        (
            "gnode spring model (paper preset) with scales",
            model_json(Variant::Gnode, &sg, true, true),
            sg.clone(),
            ss.clone(),
        ),
        (
            "node spring model",
            model_json(Variant::Node, &sg, false, false),
            sg.clone(),
            ss.clone(),
        ),
        (
            "cdgnode pendulum model with scales",
            model_json(Variant::Cdgnode, &pg, false, true),
            pg.clone(),
            ps.clone(),
        ),
    ];
    let baseline_json = |kind: Kind, g: &Graph| {
        let (_, template) = mcgnode::testing::random_model(Variant::Gnode, g, 3).expect("model");
        let mut hyper = BaselineHyper::new(kind, g.dim, 1);
        (hyper.hidden, hyper.latent, hyper.rounds) = (4, 3, 1);
        let net = BaselineNet::new(hyper, &mut rand_chacha::ChaCha8Rng::seed_from_u64(4))
            .expect("baseline");
        let file = BaselineFile {
            format: mcgnode::baselines::FORMAT.into(),
            crate_version: env!("CARGO_PKG_VERSION").into(),
            hyper: net.hyper.clone(),
            trained_on: Some(template.file.trained_on.clone()),
            training: template.file.training.clone(),
            weights: net.store.weights().expect("weights"),
        };
        let p = dir.path().join("baseline.json");
        file.save(&p).expect("save baseline");
        std::fs::read_to_string(&p).expect("read baseline")
    };
    let baselines = vec![
        (
            "lgn spring baseline",
            baseline_json(Kind::Lgn, &sg),
            sg.clone(),
            ss.clone(),
        ),
        (
            "gns pendulum baseline",
            baseline_json(Kind::Gns, &pg),
            pg.clone(),
            ps.clone(),
        ),
    ];
    for (what, text, g, s) in models.iter().chain(&baselines) {
        let p = dir.path().join("check.json");
        std::fs::write(&p, text).expect("write");
        let m = load_any_model(&ModelRef::File(p.clone()))
            .unwrap_or_else(|e| panic!("seed {what} does not load: {e}"));
        let mut out = vec![0.0; g.ndof()];
        m.dynamics
            .acceleration(g, s, &mut out)
            .unwrap_or_else(|e| panic!("seed {what} does not run: {e}"));
    }
    Seeds {
        bags,
        bag_messages: vec![("spring", spring_msgs), ("pendulum", pendulum_msgs)],
        cdr,
        models,
        baselines,
    }
}

/// A file a property rewrites for each case (the readers take paths), in
/// memory (/dev/shm) where there is one: a disk stalls now and then.
fn scratch(name: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir_in("/dev/shm")
        .or_else(|_| tempfile::tempdir())
        .expect("tempdir");
    let path = dir.path().join(name);
    (dir, path)
}

/// Replaces the scratch file: a new file rather than a truncated one, which
/// ext4 would flush to disk on every close (milliseconds a case).
fn put(path: &Path, bytes: &[u8]) {
    let _ = std::fs::remove_file(path);
    std::fs::write(path, bytes).expect("write scratch file");
}

// ---------------------------------------------------------------- MCAP

fn read_bag(path: &Path, bytes: &[u8]) -> Outcome {
    put(path, bytes);
    match read_trajectories(path) {
        Ok(_) => Outcome::Accepted,
        Err(e) => rejected(&e),
    }
}

#[test]
fn mutated_mcap_bytes() {
    let s = seeds();
    let (_dir, path) = scratch("bag.mcap");
    run(
        "MCAP bytes",
        MCAP_BYTE_CASES,
        (any::<Index>(), mutations()),
        |g, (seed, muts)| {
            let (what, bytes) = &s.bags[seed.index(s.bags.len())];
            let data = mutated(bytes, &muts);
            g.case(
                || format!("{what} with {muts:?}"),
                || read_bag(&path, &data),
            )
        },
    );
}

/// An edit of a bag's message list: the container stays valid, the content not.
#[derive(Clone, Debug)]
enum MessageEdit {
    /// Mutate the CDR bytes of one message.
    Bytes(Index, Vec<Mutation>),
    /// Drop one message.
    Drop(Index),
    /// Write one message twice.
    Duplicate(Index),
    /// Swap two messages (and their log times).
    Swap(Index, Index),
    /// Move one message to a second ParticleState topic.
    Topic(Index),
    /// Change one field of one decoded message before encoding it.
    Field(Index, FieldEdit),
}

/// Field-level edits of a ParticleState that CDR bytes rarely reach.
#[derive(Clone, Debug)]
enum FieldEdit {
    TrajectoryId(u32),
    Step(u32),
    Stamp(i32, u32),
    Dimension(u8),
    System(String),
    FieldStatus(u8),
    Velocities(bool),
    Accelerations(bool),
    Mass(f64),
    EdgeB(u32),
    EdgeKind(u8),
    Anchor(f64),
    Gravity(f64),
}

fn odd_f64() -> impl Strategy<Value = f64> {
    prop::sample::select(vec![
        0.0,
        -0.0,
        -1.0,
        1e-300,
        1e300,
        f64::MAX,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ])
}

fn field_edit() -> impl Strategy<Value = FieldEdit> {
    prop_oneof![
        prop_oneof![Just(0u32), Just(1), any::<u32>()].prop_map(FieldEdit::TrajectoryId),
        prop_oneof![Just(0u32), Just(1), Just(2), any::<u32>()].prop_map(FieldEdit::Step),
        (
            prop_oneof![
                Just(0),
                Just(-1),
                Just(i32::MIN),
                Just(i32::MAX),
                any::<i32>()
            ],
            prop_oneof![
                Just(0u32),
                Just(999_999_999),
                Just(1_000_000_000),
                any::<u32>()
            ]
        )
            .prop_map(|(s, n)| FieldEdit::Stamp(s, n)),
        prop_oneof![0u8..5, any::<u8>()].prop_map(FieldEdit::Dimension),
        prop::sample::select(vec!["", "spring", "pendulum", "cube", "\u{0}"])
            .prop_map(|s| FieldEdit::System(s.to_string())),
        prop_oneof![0u8..3, any::<u8>()].prop_map(FieldEdit::FieldStatus),
        any::<bool>().prop_map(FieldEdit::Velocities),
        any::<bool>().prop_map(FieldEdit::Accelerations),
        odd_f64().prop_map(FieldEdit::Mass),
        prop_oneof![0u32..6, any::<u32>()].prop_map(FieldEdit::EdgeB),
        prop_oneof![0u8..3, any::<u8>()].prop_map(FieldEdit::EdgeKind),
        odd_f64().prop_map(FieldEdit::Anchor),
        odd_f64().prop_map(FieldEdit::Gravity),
    ]
}

fn message_edit() -> impl Strategy<Value = MessageEdit> {
    prop_oneof![
        3 => (any::<Index>(), mutations()).prop_map(|(i, m)| MessageEdit::Bytes(i, m)),
        1 => any::<Index>().prop_map(MessageEdit::Drop),
        1 => any::<Index>().prop_map(MessageEdit::Duplicate),
        1 => (any::<Index>(), any::<Index>()).prop_map(|(a, b)| MessageEdit::Swap(a, b)),
        1 => any::<Index>().prop_map(MessageEdit::Topic),
        3 => (any::<Index>(), field_edit()).prop_map(|(i, f)| MessageEdit::Field(i, f)),
    ]
}

fn edit_field(m: &mut ParticleState, f: &FieldEdit) {
    match f {
        FieldEdit::TrajectoryId(v) => m.trajectory_id = *v,
        FieldEdit::Step(v) => m.step = *v,
        FieldEdit::Stamp(s, n) => {
            m.header.stamp.sec = *s;
            m.header.stamp.nanosec = *n;
        }
        FieldEdit::Dimension(d) => m.dimension = *d,
        FieldEdit::System(s) => m.system.clone_from(s),
        FieldEdit::FieldStatus(v) => m.field_status = *v,
        FieldEdit::Velocities(clear) => {
            if *clear {
                m.velocities.clear();
            } else {
                m.velocities.pop();
            }
        }
        FieldEdit::Accelerations(clear) => {
            if *clear {
                m.accelerations.clear();
            } else if let Some(a) = m.accelerations.first().copied() {
                m.accelerations.push(a);
            }
        }
        FieldEdit::Mass(x) => {
            if let Some(v) = m.masses.first_mut() {
                *v = *x;
            }
        }
        FieldEdit::EdgeB(b) => {
            if let Some(v) = m.edge_b.first_mut() {
                *v = *b;
            }
        }
        FieldEdit::EdgeKind(k) => {
            if let Some(v) = m.edge_kind.first_mut() {
                *v = *k;
            }
        }
        FieldEdit::Anchor(x) => match m.anchors.first_mut() {
            Some(a) => a.x = *x,
            None => m.anchors.push(mcgnode::data::msg::Point {
                x: *x,
                y: 0.0,
                z: 0.0,
            }),
        },
        FieldEdit::Gravity(x) => m.gravity.y = *x,
    }
}

#[test]
fn mcap_with_mutated_messages() {
    let s = seeds();
    let (_dir, path) = scratch("bag.mcap");
    let schema = particle_state_schema();
    let v1_schema = mcgnode::data::msg::ros2msg_schema(PARTICLE_STATE_MSG_V1, &[]);
    let edits = prop::collection::vec(message_edit(), 1..=4);
    run(
        "MCAP messages",
        MCAP_MESSAGE_CASES,
        (any::<Index>(), edits, 0u8..8),
        |g, (seed, edits, options)| {
            let (what, msgs) = &s.bag_messages[seed.index(s.bag_messages.len())];
            g.case(
                || format!("{what} bag ({options}) with {edits:?}"),
                || {
                    let mut msgs = msgs.clone();
                    for e in &edits {
                        if let MessageEdit::Field(i, f) = e {
                            let n = msgs.len();
                            edit_field(&mut msgs[i.index(n)], f);
                        }
                    }
                    let v1 = options & 1 == 1;
                    let mut enc = encoded(&msgs, v1);
                    for e in &edits {
                        let n = enc.len();
                        if n == 0 {
                            break;
                        }
                        match e {
                            MessageEdit::Bytes(i, muts) => {
                                let cdr = &mut enc[i.index(n)].2;
                                *cdr = mutated(cdr, muts);
                            }
                            MessageEdit::Drop(i) => {
                                enc.remove(i.index(n));
                            }
                            MessageEdit::Duplicate(i) => {
                                let m = enc[i.index(n)].clone();
                                enc.insert(i.index(n), m);
                            }
                            MessageEdit::Swap(a, b) => enc.swap(a.index(n), b.index(n)),
                            MessageEdit::Topic(i) => enc[i.index(n)].0 = "/other".into(),
                            MessageEdit::Field(..) => {}
                        }
                    }
                    // Both the current and the first layout, with and
                    // without chunk compression.
                    let schema = if v1 { &v1_schema } else { &schema };
                    let opts = match options >> 1 {
                        0 => no_crcs().compression(None),
                        1 => no_crcs().use_chunks(false),
                        _ => mcap::WriteOptions::new(),
                    };
                    read_bag(&path, &raw_bag(opts, &enc, schema))
                },
            )
        },
    );
}

// ---------------------------------------------------------------- CDR

#[test]
fn mutated_cdr_messages() {
    let s = seeds();
    run(
        "CDR messages",
        CDR_CASES,
        (any::<Index>(), mutations()),
        |g, (seed, muts)| {
            let (what, layout, bytes) = &s.cdr[seed.index(s.cdr.len())];
            let data = mutated(bytes, &muts);
            g.case(
                || format!("{what} with {muts:?}"),
                || {
                    let m = match ParticleState::from_cdr_as(&data, *layout) {
                        Ok(m) => m,
                        Err(e) => return rejected(&e),
                    };
                    // Everything the bag reader and the node ask of a message.
                    if let Err(e) = m.field() {
                        return rejected(&e);
                    }
                    if let Err(e) = m.to_parts_positions_only() {
                        return rejected(&e);
                    }
                    match m.to_parts() {
                        Ok(_) => Outcome::Accepted,
                        Err(e) => rejected(&e),
                    }
                },
            )
        },
    );
}

// ---------------------------------------------------------------- model files

/// An edit of a model file's JSON.
#[derive(Clone, Debug)]
enum JsonEdit {
    /// Replace the k-th number of the text by another token.
    Number(Index, &'static str),
    /// Set the k-th object member whose value is a number (a
    /// hyperparameter, scale or count rather than a weight) to a value.
    Setting(Index, &'static str),
    /// Delete member j of the k-th object.
    DeleteKey(Index, Index),
    /// Change the length of the k-th array.
    Resize(Index, Resize),
    /// Replace the k-th value of any kind by one of [`VALUES`] (often of
    /// another type).
    Retype(Index, &'static str),
}

#[derive(Clone, Copy, Debug)]
enum Resize {
    Clear,
    Pop,
    PushLast,
    Halve,
    Double,
}

/// Replacement tokens: huge, negative, fractional, out of range, non-finite
/// (not JSON, which the parser must refuse), and other types.
const NUMBERS: &[&str] = &[
    "0",
    "-1",
    "1",
    "2",
    "3",
    "4",
    "7",
    "1000000",
    "4294967296",
    "1e15",
    "18446744073709551615",
    "18446744073709551616",
    "-9223372036854775808",
    "1e308",
    "-1e308",
    "1e999",
    "NaN",
    "Infinity",
    "-0",
    "0.5",
    "1e-320",
    "null",
    "\"7\"",
];

/// Replacement values (valid JSON) for [`JsonEdit::Setting`] and [`JsonEdit::Retype`].
const VALUES: &[&str] = &[
    "0",
    "-1",
    "1",
    "2",
    "3",
    "5",
    "100",
    "1000000",
    "4294967296",
    "1000000000000000",
    "18446744073709551615",
    "1e308",
    "-1e308",
    "0.5",
    "null",
    "true",
    "\"x\"",
    "[]",
    "{}",
    "[1, 2]",
];

fn json_edit() -> impl Strategy<Value = JsonEdit> {
    let number = prop::sample::select(NUMBERS);
    let value = prop::sample::select(VALUES);
    prop_oneof![
        2 => (any::<Index>(), number).prop_map(|(i, t)| JsonEdit::Number(i, t)),
        3 => (any::<Index>(), value.clone()).prop_map(|(i, v)| JsonEdit::Setting(i, v)),
        1 => (any::<Index>(), any::<Index>()).prop_map(|(i, j)| JsonEdit::DeleteKey(i, j)),
        2 => (
            any::<Index>(),
            prop::sample::select(vec![
                Resize::Clear,
                Resize::Pop,
                Resize::PushLast,
                Resize::Halve,
                Resize::Double
            ])
        )
            .prop_map(|(i, r)| JsonEdit::Resize(i, r)),
        1 => (any::<Index>(), value).prop_map(|(i, v)| JsonEdit::Retype(i, v)),
    ]
}

/// Calls `f` on every value of a JSON tree in document order, each before
/// its children.
fn visit(v: &mut serde_json::Value, f: &mut dyn FnMut(&mut serde_json::Value)) {
    f(v);
    match v {
        serde_json::Value::Array(a) => a.iter_mut().for_each(|x| visit(x, f)),
        serde_json::Value::Object(o) => o.values_mut().for_each(|x| visit(x, f)),
        _ => {}
    }
}

/// Applies `edit` to the k-th value (document order, k modulo their count)
/// for which `pick` holds; to none if there is none.
fn nth(
    root: &mut serde_json::Value,
    k: Index,
    pick: &dyn Fn(&serde_json::Value) -> bool,
    edit: &mut dyn FnMut(&mut serde_json::Value),
) {
    let mut count = 0;
    visit(root, &mut |v| count += usize::from(pick(v)));
    if count == 0 {
        return;
    }
    let target = k.index(count);
    let mut i = 0;
    visit(root, &mut |v| {
        if pick(v) {
            if i == target {
                edit(v);
            }
            i += 1;
        }
    });
}

fn parse(s: &str) -> serde_json::Value {
    serde_json::from_str(s).expect("replacement values are JSON")
}

/// Spans of the number tokens of a JSON text (outside strings).
fn number_spans(text: &str) -> Vec<(usize, usize)> {
    let b = text.as_bytes();
    let (mut out, mut i, mut in_str) = (vec![], 0, false);
    while i < b.len() {
        let c = b[i];
        if in_str {
            match c {
                b'\\' => i += 1,
                b'"' => in_str = false,
                _ => {}
            }
            i += 1;
        } else if c == b'"' {
            in_str = true;
            i += 1;
        } else if c == b'-' || c.is_ascii_digit() {
            let start = i;
            while i < b.len() && matches!(b[i], b'-' | b'+' | b'.' | b'e' | b'E' | b'0'..=b'9') {
                i += 1;
            }
            out.push((start, i));
        } else {
            i += 1;
        }
    }
    out
}

/// The JSON text after the edits: tree edits first, then token replacements
/// (which can write what a JSON tree cannot hold, such as `NaN`).
fn edit_json(text: &str, edits: &[JsonEdit]) -> String {
    let mut root: serde_json::Value = serde_json::from_str(text).expect("seed is JSON");
    for e in edits {
        match e {
            JsonEdit::Setting(k, v) => {
                let numbers = |o: &serde_json::Map<String, serde_json::Value>| -> Vec<String> {
                    o.iter()
                        .filter(|(_, x)| x.is_number())
                        .map(|(k, _)| k.clone())
                        .collect()
                };
                let mut count = 0;
                visit(&mut root, &mut |x| {
                    count += x.as_object().map_or(0, |o| numbers(o).len());
                });
                if count > 0 {
                    let mut left = k.index(count);
                    visit(&mut root, &mut |x| {
                        let Some(o) = x.as_object_mut() else { return };
                        let keys = numbers(o);
                        if left < keys.len() {
                            o.insert(keys[left].clone(), parse(v));
                            left = usize::MAX;
                        } else if left != usize::MAX {
                            left -= keys.len();
                        }
                    });
                }
            }
            JsonEdit::DeleteKey(k, j) => nth(&mut root, *k, &|v| v.is_object(), &mut |o| {
                let o = o.as_object_mut().expect("object");
                if !o.is_empty() {
                    let key = o.keys().nth(j.index(o.len())).cloned().expect("key");
                    o.remove(&key);
                }
            }),
            JsonEdit::Resize(k, r) => nth(&mut root, *k, &|v| v.is_array(), &mut |a| {
                let a = a.as_array_mut().expect("array");
                match r {
                    Resize::Clear => a.clear(),
                    Resize::Pop => {
                        a.pop();
                    }
                    Resize::PushLast => {
                        let last = a.last().cloned().unwrap_or(serde_json::Value::from(0));
                        a.push(last);
                    }
                    Resize::Halve => a.truncate(a.len() / 2),
                    Resize::Double => {
                        let copy = a.clone();
                        a.extend(copy);
                    }
                }
            }),
            JsonEdit::Retype(k, v) => nth(&mut root, *k, &|_| true, &mut |x| *x = parse(v)),
            JsonEdit::Number(..) => {}
        }
    }
    let mut text = serde_json::to_string_pretty(&root).expect("JSON");
    for e in edits {
        if let JsonEdit::Number(k, token) = e {
            let spans = number_spans(&text);
            if !spans.is_empty() {
                let (a, b) = spans[k.index(spans.len())];
                text.replace_range(a..b, token);
            }
        }
    }
    text
}

/// Byte mutations, byte mutations kept ASCII, or JSON edits of a model file.
#[derive(Clone, Debug)]
enum ModelMutation {
    Bytes(Vec<Mutation>),
    /// Most raw mutations break UTF-8, which the reader refuses first;
    /// these reach the JSON parser.
    Ascii(Vec<Mutation>),
    Json(Vec<JsonEdit>),
}

fn model_mutation() -> impl Strategy<Value = ModelMutation> {
    prop_oneof![
        1 => mutations().prop_map(ModelMutation::Bytes),
        1 => mutations().prop_map(ModelMutation::Ascii),
        3 => prop::collection::vec(json_edit(), 1..=3).prop_map(ModelMutation::Json),
    ]
}

/// Loads a model file both ways and runs what loads on a small graph.
fn load_and_run(path: &Path, graph: &Graph, state: &State) -> Outcome {
    // The GNODE family's own reader (a baseline file is refused by format).
    if let Err(e) = ModelFile::load(path) {
        if e.to_string().trim().is_empty() {
            return Outcome::Rejected(String::new());
        }
    }
    let m = match load_any_model(&ModelRef::File(path.to_path_buf())) {
        Ok(m) => m,
        Err(e) => return rejected(&e),
    };
    let d = &m.dynamics;
    let _ = d.describe();
    if let Err(e) = d.supports(graph) {
        return rejected(&e);
    }
    let mut out = vec![0.0; graph.ndof()];
    if let Err(e) = d.acceleration(graph, state, &mut out) {
        return rejected(&e);
    }
    match d.forces(graph, state) {
        Ok(_) => Outcome::Accepted,
        Err(e) => rejected(&e),
    }
}

fn model_property(
    name: &'static str,
    cases: u32,
    files: &'static [(&'static str, String, Graph, State)],
) {
    let (_dir, path) = scratch("model.json");
    run(
        name,
        cases,
        (any::<Index>(), model_mutation()),
        |g, (seed, mutation)| {
            let (what, text, graph, state) = &files[seed.index(files.len())];
            g.case(
                || format!("{what} with {mutation:?}"),
                || {
                    let bytes = match &mutation {
                        ModelMutation::Bytes(m) => mutated(text.as_bytes(), m),
                        ModelMutation::Ascii(m) => {
                            let mut b = mutated(text.as_bytes(), m);
                            b.iter_mut().for_each(|x| *x &= 0x7f);
                            b
                        }
                        ModelMutation::Json(e) => edit_json(text, e).into_bytes(),
                    };
                    put(&path, &bytes);
                    load_and_run(&path, graph, state)
                },
            )
        },
    );
}

#[test]
fn mutated_model_files() {
    model_property("model files", MODEL_CASES, &seeds().models);
}

#[test]
fn mutated_baseline_files() {
    model_property("baseline files", BASELINE_CASES, &seeds().baselines);
}

// ---------------------------------------------------------------- GNS

/// A seed GNS file: what it is, its metadata, its bytes.
type GnsSeed = (&'static str, GnsMetadata, Vec<u8>);

/// Valid GNS TFRecord files (2D with a kinematic particle, 3D) and metadata.
fn gns_seeds() -> (Vec<GnsSeed>, String) {
    let meta_text = r#"{"dim": 2, "dt": 0.0025, "default_connectivity_radius": 0.015,
        "bounds": [[0.1, 0.9], [0.1, 0.9]], "sequence_length": 3}"#
        .to_string();
    let path = Path::new("metadata.json");
    let m2 = GnsMetadata::from_json(&meta_text, path, None).expect("seed metadata");
    let m3 = GnsMetadata {
        dim: 3,
        ..m2.clone()
    };
    let steps = |n: usize, dim: usize| -> Vec<Vec<f32>> {
        (0..4)
            .map(|t| (0..n * dim).map(|i| 0.1 + 0.01 * (i + t) as f32).collect())
            .collect()
    };
    let mut two = encode_record(0, &[5, 5, 3], &steps(3, 2));
    two.extend(encode_record(1, &[5, 3], &steps(2, 2)));
    let three = encode_record(7, &[6, 6], &steps(2, 3));
    for (m, b) in [(&m2, &two), (&m3, &three)] {
        gns_trajectories(b, Path::new("seed.tfrecord"), m, "gns").expect("seed file reads");
    }
    (
        vec![("2D file", m2, two), ("3D file", m3, three)],
        meta_text,
    )
}

/// Reads GNS bytes; accepted trajectories must be valid systems.
fn read_gns_bytes(data: &[u8], meta: &GnsMetadata) -> Outcome {
    match gns_trajectories(data, Path::new("fuzz.tfrecord"), meta, "gns") {
        Ok(trs) => {
            for tr in &trs {
                tr.graph.validate().expect("an accepted graph is valid");
                for s in &tr.samples {
                    s.state
                        .validate(&tr.graph)
                        .expect("an accepted state is valid");
                }
            }
            Outcome::Accepted
        }
        Err(e) => rejected(&e),
    }
}

#[test]
fn mutated_gns_records() {
    let (seeds, _) = gns_seeds();
    run(
        "GNS TFRecord",
        GNS_CASES,
        (any::<Index>(), any::<bool>(), mutations()),
        |g, (seed, reframe, muts)| {
            let (what, meta, bytes) = &seeds[seed.index(seeds.len())];
            let data = if reframe {
                // The first record's payload mutated, framed with good CRCs.
                let len = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
                mcgnode::data::import::tfrecord::frame(&mutated(&bytes[12..12 + len], &muts))
            } else {
                mutated(bytes, &muts)
            };
            g.case(
                || format!("{what} (reframed: {reframe}) with {muts:?}"),
                || read_gns_bytes(&data, meta),
            )
        },
    );
}

#[test]
fn mutated_gns_metadata() {
    let (seeds, text) = gns_seeds();
    run(
        "GNS metadata",
        GNS_METADATA_CASES,
        mutations(),
        |g, muts| {
            let data = mutated(text.as_bytes(), &muts);
            g.case(
                || format!("metadata.json with {muts:?}"),
                || {
                    let t = String::from_utf8_lossy(&data);
                    match GnsMetadata::from_json(&t, Path::new("metadata.json"), None) {
                        Ok(m) if m.dim == 2 => read_gns_bytes(&seeds[0].2, &m),
                        Ok(m) => read_gns_bytes(&seeds[1].2, &m),
                        Err(e) => rejected(&e),
                    }
                },
            )
        },
    );
}
