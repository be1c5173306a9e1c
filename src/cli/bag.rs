//! `mcgnode bag info`, `repair`, `draw`, `observe`; `import` is in `import.rs`.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::data::bag::{read_bags, scan_input, ReadOptions};
use crate::data::source::{bag_parts, Storage};

/// Options of `bag`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    #[command(subcommand)]
    command: BagCommand,
}

#[derive(clap::Subcommand, Debug, Clone)]
enum BagCommand {
    /// Print each bag's files, topics with message counts, and its
    /// ParticleState trajectories: systems, particles, states, duration and
    /// the field the messages state.
    Info(InfoArgs),
    /// Rewrite a bag cut short by a crash (no summary, footer or end magic, a
    /// torn last record) as a complete, indexed MCAP: every message up to the
    /// last whole record is kept, in order. Like `ros2 bag reindex`.
    Repair(RepairArgs),
    /// Draw one visualization_msgs/MarkerArray of a recording (what RViz and
    /// Foxglove show: particles, edges, predicted paths, force arrows) as a PNG.
    Draw(DrawArgs),
    /// Write a bag as a tracker would report it: positions only (velocities
    /// and accelerations left empty), with Gaussian position noise, an uneven
    /// rate and dropped states as asked. The system description (metadata,
    /// field) is kept, so `replay` and the node read it as before.
    Observe(ObserveArgs),
    /// Import another project's dataset as a bag: `--from gns` (TFRecord
    /// SequenceExamples and metadata.json, Sanchez-Gonzalez et al. 2020).
    /// Interaction radius and dt come from the metadata, kinematic
    /// (boundary) particles from the types, velocities from finite
    /// differences of the positions.
    Import(super::import::ImportArgs),
}

/// Options of `bag observe`.
#[derive(clap::Args, Debug, Clone)]
pub struct ObserveArgs {
    /// The bag to observe (MCAP, rosbag2 directory or .db3).
    pub input: PathBuf,
    /// The MCAP file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Position noise (standard deviation) as a fraction of the particle
    /// spacing (the median edge length in the first state; the median
    /// nearest-neighbour distance without edges): 0.001 is 0.1 %.
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
    /// Keep about every N-th state.
    #[arg(long, default_value_t = 1)]
    pub thin: usize,
    /// Spread of the kept states' spacing: each next one N·(1 ± u) states on,
    /// u uniform in [0, UNEVEN].
    #[arg(long, default_value_t = 0.0)]
    pub uneven: f64,
    /// Probability of dropping a kept state.
    #[arg(long, default_value_t = 0.0)]
    pub drop: f64,
    /// Seed of the noise and the choices.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The ParticleState topic to read, when the bag holds several.
    #[arg(long)]
    pub topic: Option<String>,
}

/// Options of `bag draw`.
#[derive(clap::Args, Debug, Clone)]
pub struct DrawArgs {
    /// An MCAP file recorded by `mcgnode serve` (or any with MarkerArray messages).
    pub bag: PathBuf,
    /// The PNG to write.
    #[arg(long)]
    pub png: PathBuf,
    /// Which MarkerArray, counted from 0 in log-time order (default: the last).
    #[arg(long)]
    pub index: Option<usize>,
}

/// Options of `bag info`.
#[derive(clap::Args, Debug, Clone)]
pub struct InfoArgs {
    /// Bags: MCAP files, rosbag2 directories or .db3 files.
    #[arg(required = true)]
    pub paths: Vec<PathBuf>,
    /// The ParticleState topic to describe, when a bag holds several.
    #[arg(long)]
    pub topic: Option<String>,
}

/// Options of `bag repair`.
#[derive(clap::Args, Debug, Clone)]
pub struct RepairArgs {
    /// The damaged MCAP file.
    pub input: PathBuf,
    /// Where to write the repaired MCAP (must differ from the input).
    pub output: PathBuf,
}

/// Runs `bag`.
pub fn run(a: Args) -> Result<()> {
    match a.command {
        BagCommand::Info(a) => info(a),
        BagCommand::Repair(a) => repair(a),
        BagCommand::Draw(a) => draw(&a),
        BagCommand::Observe(a) => observe(&a),
        BagCommand::Import(a) => super::import::run(&a),
    }
}

/// Writes `a.input` as a tracker would report it to `a.out`.
fn observe(a: &ObserveArgs) -> Result<()> {
    use crate::data::observe::{observe, Observation};
    let bag = read_bags(
        std::slice::from_ref(&a.input),
        &ReadOptions {
            topic: a.topic.clone(),
        },
    )
    .context("reading the bag")?;
    let o = Observation {
        noise: a.noise,
        thin: a.thin,
        uneven: a.uneven,
        drop: a.drop,
        seed: a.seed,
    };
    let (seen, sigma) = observe(&bag.trajectories, &o)?;
    let mut meta = bag.metadata.clone();
    meta.insert(
        "observed".into(),
        format!(
            "positions only; noise {} of the spacing (sigma {sigma:.3e}); thin {}, uneven {}, \
             drop {}, seed {}",
            a.noise, a.thin, a.uneven, a.drop, a.seed
        ),
    );
    crate::data::write_positions_only(&a.out, &seen, &meta, bag.field.as_ref())
        .with_context(|| format!("writing {}", a.out.display()))?;
    let states: usize = seen.iter().map(|t| t.samples.len()).sum();
    println!(
        "wrote {}: {} trajectories, {states} position-only states, noise sigma {sigma:.3e}",
        a.out.display(),
        seen.len()
    );
    Ok(())
}

/// Per system name: trajectories, particle counts, dimensions, states,
/// longest span in seconds.
type SystemSummary = (usize, Vec<usize>, Vec<usize>, usize, f64);

fn info(a: InfoArgs) -> Result<()> {
    for path in &a.paths {
        println!("{}", path.display());
        print_files(path)?;
        print_topics(path)?;
        print_particle_states(path, a.topic.as_deref())?;
    }
    Ok(())
}

/// Prints the files of the bag at `path`: storage and compression.
fn print_files(path: &std::path::Path) -> Result<()> {
    for part in bag_parts(path)? {
        let storage = match part.storage {
            Storage::Mcap => "mcap",
            Storage::Sqlite3 => "sqlite3",
        };
        let mut how = vec![storage.to_string()];
        if let Some(c) = part.file_compression {
            how.push(format!("file compression {}", c.name()));
        }
        if let Some(c) = part.message_compression {
            how.push(format!("message compression {}", c.name()));
        }
        println!("  file: {} ({})", part.path.display(), how.join(", "));
    }
    Ok(())
}

/// Prints the message count and duration of the bag at `path`, and its
/// topics with their types and message counts.
fn print_topics(path: &std::path::Path) -> Result<()> {
    // topic -> (type, count, first, last log time)
    let mut topics: BTreeMap<String, (String, usize, u64, u64)> = BTreeMap::new();
    scan_input(path, |m| {
        let e = topics
            .entry(m.topic.to_string())
            .or_insert_with(|| (m.schema_name.to_string(), 0, u64::MAX, 0));
        e.1 += 1;
        e.2 = e.2.min(m.log_time);
        e.3 = e.3.max(m.log_time);
        Ok(())
    })
    .with_context(|| format!("reading {}", path.display()))?;
    let (first, last) = topics
        .values()
        .fold((u64::MAX, 0), |(a, b), t| (a.min(t.2), b.max(t.3)));
    let total: usize = topics.values().map(|t| t.1).sum();
    println!(
        "  messages: {total}, duration: {:.3} s",
        if total == 0 {
            0.0
        } else {
            (last - first) as f64 * 1e-9
        }
    );
    println!("  topics:");
    for (t, (ty, n, _, _)) in &topics {
        println!("    {t}  {ty}  {n} messages");
    }
    Ok(())
}

/// Prints what the ParticleState trajectories of the bag at `path` hold:
/// systems, field, contacts, derived velocities and metadata keys.
fn print_particle_states(path: &std::path::Path, topic: Option<&str>) -> Result<()> {
    let bag = read_bags(
        &[path.to_path_buf()],
        &ReadOptions {
            topic: topic.map(str::to_string),
        },
    )?;
    if bag.trajectories.is_empty() {
        println!("  no ParticleState trajectories");
        return Ok(());
    }
    println!("  ParticleState topic: {}", bag.topic);
    print_systems(&bag.trajectories);
    let field = match &bag.field {
        None => "unknown (the messages do not state it)".to_string(),
        Some(f) if f.is_free() => "none (closed when there are no anchors)".to_string(),
        Some(f) => format!(
            "gravity {} along -y, drag {}, force {:?}",
            f.gravity, f.drag, f.force
        ),
    };
    println!("  field: {field}");
    println!("  contacts: {}", contacts(&bag.trajectories));
    if !bag.derived_velocities.is_empty() {
        println!(
            "  velocities: derived from positions and stamps (position-only) in {} trajectories",
            bag.derived_velocities.len()
        );
    }
    if !bag.metadata.is_empty() {
        let keys: Vec<&str> = bag.metadata.keys().map(String::as_str).collect();
        println!("  mcgnode metadata: {}", keys.join(", "));
    }
    Ok(())
}

/// Prints the trajectories per system name: count, particle counts,
/// dimensions, states and longest span.
fn print_systems(trajs: &[crate::system::Trajectory]) {
    let mut systems: BTreeMap<String, SystemSummary> = BTreeMap::new();
    for tr in trajs {
        let name = if tr.system.is_empty() {
            "(unnamed)".to_string()
        } else {
            tr.system.clone()
        };
        let e = systems.entry(name).or_default();
        e.0 += 1;
        if !e.1.contains(&tr.graph.n()) {
            e.1.push(tr.graph.n());
        }
        if !e.2.contains(&tr.graph.dim) {
            e.2.push(tr.graph.dim);
        }
        e.3 += tr.samples.len();
        e.4 = e.4.max(tr.samples.last().map_or(0.0, |s| s.t));
    }
    println!("  systems:");
    for (name, (n, parts, dims, states, span)) in &systems {
        let list = |v: &[usize]| {
            v.iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join("/")
        };
        println!(
            "    {name}: {n} trajectories, {} particles, {}D, {states} states, longest {span:.3} s",
            list(parts),
            list(dims)
        );
    }
}

/// The interaction radii and kinematic particle counts of the trajectories:
/// "radius 1 (particles closer touch), 120 kinematic particles" or "none",
/// and the periodic box ("periodic box [0, 2.4) x [0, 2.4) (periodic x, y)"
/// or "not periodic").
fn contacts(trajs: &[crate::system::Trajectory]) -> String {
    let mut radii: Vec<f64> = vec![];
    let mut kinematic: Vec<usize> = vec![];
    for tr in trajs {
        if !radii.contains(&tr.graph.interaction_radius) {
            radii.push(tr.graph.interaction_radius);
        }
        if !kinematic.contains(&tr.graph.n_kinematic()) {
            kinematic.push(tr.graph.n_kinematic());
        }
    }
    let join = |v: Vec<String>| v.join("/");
    let radius = if radii == [0.0] {
        "none (interaction radius 0: fixed edges only)".to_string()
    } else {
        format!(
            "interaction radius {} (closer pairs touch)",
            join(radii.iter().map(ToString::to_string).collect())
        )
    };
    let held = if kinematic == [0] {
        "no kinematic particles".to_string()
    } else {
        format!(
            "{} kinematic particles",
            join(kinematic.iter().map(ToString::to_string).collect())
        )
    };
    let mut boxes: Vec<String> = vec![];
    for tr in trajs {
        let b = tr.graph.periodic().map_or("not periodic".into(), |b| {
            format!("periodic {}", b.describe())
        });
        if !boxes.contains(&b) {
            boxes.push(b);
        }
    }
    format!("{radius}, {held}, {}", boxes.join("/"))
}

fn repair(a: RepairArgs) -> Result<()> {
    let r = crate::data::repair::repair(&a.input, &a.output)?;
    println!(
        "kept {} messages on {} channels and {} metadata records; wrote {}",
        r.messages,
        r.channels,
        r.metadata,
        a.output.display()
    );
    if r.stopped.is_empty() {
        println!("the input was complete");
    } else {
        println!("reading stopped {}", r.stopped);
    }
    Ok(())
}

/// Draws one MarkerArray of `a.bag` to `a.png`.
fn draw(a: &DrawArgs) -> Result<()> {
    use crate::ros::wire::markers::MarkerArray;
    let arrays = marker_arrays(&a.bag)?;
    let n = arrays.len();
    let i = a.index.unwrap_or(n.saturating_sub(1));
    let Some((_, topic, data)) = arrays.get(i) else {
        anyhow::bail!(
            "{} holds {n} MarkerArray messages{}; record with `serve` (markers: true) or pick \
             --index below {n}",
            a.bag.display(),
            if n == 0 { "" } else { ", not that many" }
        );
    };
    let arr: MarkerArray = crate::data::msg::decode_cdr(data)
        .with_context(|| format!("decoding MarkerArray {i} of {}", a.bag.display()))?;
    let (mut scene, stamp) = marker_scene(&arr);
    let (sec, nanosec, frame) = stamp.unwrap_or_default();
    scene.title =
        format!("{topic}, MarkerArray {i} (of {n}): stamp {sec}.{nanosec:09} s, frame {frame}");
    crate::plot::draw_scene(&a.png, &scene)?;
    println!(
        "drew MarkerArray {i} (of {n}; {} markers) to {}",
        arr.markers.len(),
        a.png.display()
    );
    Ok(())
}

/// The MarkerArray messages of the MCAP file `bag` as (log time, topic,
/// CDR bytes), in log-time order.
fn marker_arrays(bag: &std::path::Path) -> Result<Vec<(u64, String, Vec<u8>)>> {
    use crate::ros::wire::markers::MarkerArray;
    use crate::ros::wire::RosType as _;
    let bytes = std::fs::read(bag).with_context(|| format!("reading {}", bag.display()))?;
    let mut arrays = vec![];
    for m in mcap::MessageStream::new(&bytes)
        .with_context(|| format!("{} is not MCAP", bag.display()))?
    {
        let m = m.with_context(|| format!("reading {}", bag.display()))?;
        if m.channel
            .schema
            .as_ref()
            .is_some_and(|s| s.name == MarkerArray::TYPE_NAME)
        {
            arrays.push((m.log_time, m.channel.topic.clone(), m.data.into_owned()));
        }
    }
    arrays.sort_by_key(|x| x.0);
    Ok(arrays)
}

/// The scene the added markers of `arr` draw (untitled), and the stamp and
/// frame of the first of them.
fn marker_scene(
    arr: &crate::ros::wire::markers::MarkerArray,
) -> (crate::plot::Scene, Option<(i32, u32, String)>) {
    use crate::ros::wire::markers::{ARROW, CUBE_LIST, LINE_LIST, SPHERE_LIST};
    let v = |p: &crate::data::msg::Point| [p.x, p.y, p.z];
    let rgb = |c: &crate::ros::wire::markers::ColorRgba| {
        let u = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
        plotters::style::RGBColor(u(c.r), u(c.g), u(c.b))
    };
    let mut scene = crate::plot::Scene::default();
    let mut stamp = None;
    for m in arr
        .markers
        .iter()
        .filter(|m| m.action == crate::ros::wire::markers::ADD)
    {
        stamp.get_or_insert((
            m.header.stamp.sec,
            m.header.stamp.nanosec,
            m.header.frame_id.clone(),
        ));
        let color_at = |k: usize| m.colors.get(k).map_or_else(|| rgb(&m.color), rgb);
        match m.kind {
            LINE_LIST => {
                for (k, pair) in m.points.chunks_exact(2).enumerate() {
                    scene
                        .segments
                        .push((v(&pair[0]), v(&pair[1]), color_at(2 * k), m.scale.x));
                }
            }
            SPHERE_LIST => {
                for (k, p) in m.points.iter().enumerate() {
                    scene.discs.push((v(p), color_at(k), m.scale.x));
                }
            }
            CUBE_LIST => {
                for (k, p) in m.points.iter().enumerate() {
                    scene.squares.push((v(p), color_at(k), m.scale.x));
                }
            }
            ARROW if m.points.len() == 2 => {
                scene
                    .arrows
                    .push((v(&m.points[0]), v(&m.points[1]), rgb(&m.color), m.scale.x));
            }
            _ => {}
        }
    }
    (scene, stamp)
}
