//! Recording what the node sees and says to MCAP bags (the ROS 2 convention,
//! readable by mcap-ros2-support and rosbags): incoming states, predicted
//! trajectories and forces, each on its topic with its full schema.
//!
//! A chunk is finished when its oldest message has waited
//! `record_flush_seconds` (checked at each write and on the node's timer,
//! [`Recorder::flush_due`]) or at 1 MiB, and then reaches the file with a
//! provisional footer ([`crate::data::bag::commit`]): a SIGKILL loses only the
//! open chunk's messages, and leaves a summary-less MCAP that `rosbags`,
//! `mcap` and our readers read as it is. Log times never go back within a
//! recording (a message logged before the last one is logged at its time), as
//! a summary-less file is read in file order. Bags split by size or duration;
//! [`Recorder::finish`] closes the open one.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use crate::data::bag::commit::{commit_file, CommitFile, CommitHandle};
use crate::data::msg::{
    encode_cdr, ros2msg_schema, DEP_HEADER, DEP_POINT, DEP_TIME, DEP_VECTOR3, PARTICLE_STATE_MSG,
};
use crate::data::{BagMetadata, BagWriter, ChannelId, DataError, ParticleState, METADATA_NAME};
use crate::error::BoxedError;

use super::params::NodeParams;
use super::wire::{marker_array_schema, MarkerArray, ParticleForces, PredictedTrajectory, RosType};

/// `msg/PredictedTrajectory.msg`.
pub const PREDICTED_TRAJECTORY_MSG: &str = include_str!("../../msg/PredictedTrajectory.msg");
/// `msg/ParticleForces.msg`.
pub const PARTICLE_FORCES_MSG: &str = include_str!("../../msg/ParticleForces.msg");

/// Full ros2msg schema of `PredictedTrajectory` (with the nested ParticleState).
pub fn predicted_trajectory_schema() -> String {
    let state = (
        // Dependency blocks are named pkg/Type, as rosbag2 writes them.
        ParticleState::SCHEMA_NAME,
        PARTICLE_STATE_MSG,
    );
    ros2msg_schema(
        PREDICTED_TRAJECTORY_MSG,
        &[DEP_HEADER, DEP_TIME, state, DEP_VECTOR3, DEP_POINT],
    )
}

/// Full ros2msg schema of `ParticleForces`.
pub fn particle_forces_schema() -> String {
    ros2msg_schema(PARTICLE_FORCES_MSG, &[DEP_HEADER, DEP_TIME, DEP_VECTOR3])
}

/// Uncompressed bytes at which a chunk is finished whatever its age (MCAP's
/// default chunk size).
const CHUNK_BYTES: u64 = mcap::WriteOptions::DEFAULT_CHUNK_SIZE;

/// One open bag and its channels.
struct OpenBag {
    writer: BagWriter<CommitFile>,
    path: PathBuf,
    /// Commits finished chunks to the file.
    file: CommitHandle,
    opened: Instant,
    /// When the oldest message of the open chunk was written (`None`: no
    /// chunk open).
    oldest: Option<Instant>,
    /// Uncompressed bytes in the open chunk.
    chunk_bytes: u64,
    /// States, trajectories, forces, markers (the order of `Recorder::topics`).
    channels: [ChannelId; 4],
}

/// Writes the node's traffic to a sequence of bags in one folder.
pub struct Recorder {
    dir: PathBuf,
    topics: [String; 4],
    split_bytes: u64,
    split_after: Option<Duration>,
    /// `record_flush_seconds`.
    flush_after: Duration,
    /// The last log time written: later ones never go back.
    last_log_ns: u64,
    metadata: BagMetadata,
    /// Distinguishes this run's bags from earlier runs' in the same folder.
    run: u64,
    index: u32,
    open: Option<OpenBag>,
    /// Bags finished so far, in order.
    pub finished: Vec<PathBuf>,
    /// Closed for good ([`Recorder::close`]): later writes are dropped.
    closed: bool,
}

/// Why recording failed: the folder, the bag written to, or the message.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// `record_dir` cannot be created.
    #[error("cannot create record_dir {}: {source}", dir.display())]
    CreateDir {
        /// The folder.
        dir: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Writing to a bag failed.
    #[error("recording to {}: {source}", path.display())]
    Write {
        /// The bag.
        path: PathBuf,
        /// Why (an I/O or MCAP error).
        source: BoxedError,
    },
    /// Closing a bag (summary and footer) failed.
    #[error("closing {}: {source}", path.display())]
    Close {
        /// The bag.
        path: PathBuf,
        /// Why.
        source: DataError,
    },
    /// A message could not be encoded for recording.
    #[error("encoding a message to record: {0}")]
    Encode(#[source] DataError),
}

crate::error::typed_errors!(RecordError);

impl Recorder {
    /// A recorder for `params.record_dir` (created if missing); no file is
    /// opened until the first message. The topic names are taken as given:
    /// the node passes them resolved ([`NodeParams::resolved`]).
    pub fn new(params: &NodeParams, model: &str) -> Result<Recorder, RecordError> {
        let dir = PathBuf::from(&params.record_dir);
        if let Err(source) = std::fs::create_dir_all(&dir) {
            return Err(RecordError::CreateDir { dir, source });
        }
        let run = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0);
        let metadata = BagMetadata {
            model: Some(model.to_string()),
            recorder: Some("mcgnode serve".to_string()),
            generator: Some(format!("mcgnode {}", env!("CARGO_PKG_VERSION"))),
            node_dt: Some(params.dt),
            node_horizon: Some(params.horizon),
            ..BagMetadata::default()
        };
        Ok(Recorder {
            dir,
            topics: [
                params.input_topic.clone(),
                params.trajectory_topic.clone(),
                params.forces_topic.clone(),
                params.markers_topic.clone(),
            ],
            split_bytes: u64::from(params.record_split_mb) << 20,
            split_after: (params.record_split_seconds > 0.0)
                .then(|| Duration::from_secs_f64(params.record_split_seconds)),
            flush_after: Duration::try_from_secs_f64(params.record_flush_seconds)
                .unwrap_or(Duration::ZERO),
            last_log_ns: 0,
            metadata,
            run,
            index: 0,
            open: None,
            finished: Vec::new(),
            closed: false,
        })
    }

    fn open_next(&mut self) -> Result<&mut OpenBag, RecordError> {
        let path = self
            .dir
            .join(format!("mcgnode-{}-{:04}.mcap", self.run, self.index));
        self.index += 1;
        let ctx = |e: BoxedError| RecordError::Write {
            path: path.clone(),
            source: e,
        };
        let file = File::create(&path).map_err(|e| ctx(e.into()))?;
        // Committed a chunk at a time, each with a provisional footer.
        let (file, handle) = commit_file(file);
        let mut writer =
            BagWriter::with_chunk_size(file, path.clone(), None).map_err(|e| ctx(e.into()))?;
        let types = [
            (
                ParticleState::TYPE_NAME,
                crate::data::msg::particle_state_schema(),
            ),
            (
                PredictedTrajectory::TYPE_NAME,
                predicted_trajectory_schema(),
            ),
            (ParticleForces::TYPE_NAME, particle_forces_schema()),
            (MarkerArray::TYPE_NAME, marker_array_schema()),
        ];
        let mut channels = [ChannelId(0); 4];
        for (c, (topic, (ty, schema))) in channels.iter_mut().zip(self.topics.iter().zip(&types)) {
            *c = writer
                .add_channel(topic, ty, schema)
                .map_err(|e| ctx(e.into()))?;
        }
        let metadata = self.metadata.to_map().map_err(|e| ctx(e.into()))?;
        writer
            .add_metadata(METADATA_NAME, &metadata)
            .map_err(|e| ctx(e.into()))?;
        // Readable (schemas, channels, metadata, no message) from the start.
        handle.commit(true).map_err(|e| ctx(e.into()))?;
        Ok(self.open.insert(OpenBag {
            writer,
            path,
            file: handle,
            opened: Instant::now(),
            oldest: None,
            chunk_bytes: 0,
            channels,
        }))
    }

    /// Finishes the open bag's open chunk, if any, and commits it to the
    /// file.
    fn flush_chunk(&mut self) -> Result<(), RecordError> {
        let Some(bag) = &mut self.open else {
            return Ok(());
        };
        bag.writer.finish_chunk().map_err(|e| RecordError::Write {
            path: bag.path.clone(),
            source: e.into(),
        })?;
        bag.oldest = None;
        bag.chunk_bytes = 0;
        bag.file.commit(true).map_err(|e| RecordError::Write {
            path: bag.path.clone(),
            source: e.into(),
        })
    }

    /// Finishes the open chunk if its oldest message will have waited
    /// `record_flush_seconds` by `now + lookahead` (the timer passes its
    /// period, so no message waits longer than that for the next tick).
    pub fn flush_due(&mut self, now: Instant, lookahead: Duration) -> Result<(), RecordError> {
        let due = (self.open.as_ref())
            .and_then(|b| b.oldest)
            .is_some_and(|t| (now + lookahead).saturating_duration_since(t) >= self.flush_after);
        if due {
            self.flush_chunk()?;
        }
        Ok(())
    }

    /// How often the node's timer should call [`Recorder::flush_due`]
    /// (`None`: never, every message finishes its chunk).
    pub fn flush_period(&self) -> Option<Duration> {
        (!self.flush_after.is_zero()).then(|| {
            (self.flush_after / 4).clamp(Duration::from_millis(5), Duration::from_millis(250))
        })
    }

    /// Closes the open bag if it reached its size or duration limit.
    fn maybe_split(&mut self) -> Result<(), RecordError> {
        let Some(bag) = &self.open else {
            return Ok(());
        };
        let size = bag.file.len();
        let too_big = self.split_bytes > 0 && size >= self.split_bytes;
        let too_old = self.split_after.is_some_and(|d| bag.opened.elapsed() >= d);
        if too_big || too_old {
            self.finish()?;
        }
        Ok(())
    }

    fn write(&mut self, which: usize, log_time_ns: u64, cdr: &[u8]) -> Result<(), RecordError> {
        if self.closed {
            return Ok(());
        }
        self.maybe_split()?;
        let log_time_ns = log_time_ns.max(self.last_log_ns);
        self.last_log_ns = log_time_ns;
        let bag = match self.open {
            Some(ref mut b) => b,
            None => self.open_next()?,
        };
        let channel = bag.channels[which];
        bag.writer
            .write(channel, log_time_ns, cdr)
            .map_err(|e| RecordError::Write {
                path: bag.path.clone(),
                source: e.into(),
            })?;
        let now = Instant::now();
        let oldest = *bag.oldest.get_or_insert(now);
        // A message record: opcode, length, 22 bytes of header, the data.
        bag.chunk_bytes += 31 + cdr.len() as u64;
        if bag.chunk_bytes >= CHUNK_BYTES || now.duration_since(oldest) >= self.flush_after {
            self.flush_chunk()?;
        }
        Ok(())
    }

    /// The served model changed: later bags name `model`, and the open bag gets
    /// a further metadata record saying so (readers take the last value of a
    /// key).
    pub fn set_model(&mut self, model: &str) -> Result<(), RecordError> {
        self.metadata.model = Some(model.to_string());
        if let Some(bag) = &mut self.open {
            let write = |e: DataError| RecordError::Write {
                path: bag.path.clone(),
                source: e.into(),
            };
            let map = self.metadata.to_map().map_err(write)?;
            // A metadata record finishes the open chunk.
            bag.writer
                .add_metadata(METADATA_NAME, &map)
                .map_err(write)?;
            bag.oldest = None;
            bag.chunk_bytes = 0;
            bag.file
                .commit(true)
                .map_err(|e| write(DataError::io(&bag.path, "writing", e)))?;
        }
        Ok(())
    }

    /// Records an incoming state, received at `log_time_ns` (ns since the epoch).
    pub fn state(&mut self, log_time_ns: u64, msg: &ParticleState) -> Result<(), RecordError> {
        let cdr = encode_cdr(msg).map_err(RecordError::Encode)?;
        self.write(0, log_time_ns, &cdr)
    }

    /// Records a prediction, published at `log_time_ns`.
    pub fn prediction(
        &mut self,
        log_time_ns: u64,
        trajectory: &PredictedTrajectory,
        forces: &ParticleForces,
    ) -> Result<(), RecordError> {
        let t = encode_cdr(trajectory).map_err(RecordError::Encode)?;
        let f = encode_cdr(forces).map_err(RecordError::Encode)?;
        self.write(1, log_time_ns, &t)?;
        self.write(2, log_time_ns, &f)
    }

    /// Records the markers of a prediction, published at `log_time_ns`.
    pub fn markers(&mut self, log_time_ns: u64, markers: &MarkerArray) -> Result<(), RecordError> {
        let m = encode_cdr(markers).map_err(RecordError::Encode)?;
        self.write(3, log_time_ns, &m)
    }

    /// Closes the open bag (summary and footer written), if any.
    pub fn finish(&mut self) -> Result<(), RecordError> {
        if let Some(bag) = self.open.take() {
            if let Err(e) = bag.writer.finish() {
                return Err(RecordError::Close {
                    path: bag.path,
                    source: e,
                });
            }
            if let Err(e) = bag.file.commit(false) {
                return Err(RecordError::Close {
                    source: DataError::io(&bag.path, "writing", e),
                    path: bag.path,
                });
            }
            self.finished.push(bag.path);
        }
        Ok(())
    }

    /// [`Recorder::finish`] for good, at shutdown: what is written later
    /// (markers drawn on another thread after the prediction they show was
    /// recorded) is dropped, where a write would open a bag nobody closes.
    pub fn close(&mut self) -> Result<(), RecordError> {
        self.closed = true;
        self.finish()
    }

    /// The folder bags go to.
    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::scan_bag;

    /// A bag that cannot be created says which, and keeps the I/O error as
    /// its source (not only its text).
    #[test]
    fn write_errors_keep_their_source() {
        let dir = tempfile::tempdir().unwrap();
        let params = NodeParams {
            record_dir: dir.path().join("rec").to_string_lossy().into_owned(),
            ..NodeParams::default()
        };
        let mut r = Recorder::new(&params, "m.json").unwrap();
        std::fs::remove_dir(dir.path().join("rec")).unwrap();
        let e = r.write(0, 0, &[0, 1, 0, 0]).unwrap_err();
        assert!(e.to_string().starts_with("recording to "), "{e}");
        let source = std::error::Error::source(&e).expect("a source");
        assert!(
            source.downcast_ref::<std::io::Error>().is_some(),
            "{source:?}"
        );
    }

    #[test]
    fn records_three_topics_and_splits_by_duration() {
        let dir = tempfile::tempdir().unwrap();
        let params = NodeParams {
            record_dir: dir.path().join("rec").to_string_lossy().into_owned(),
            record_split_seconds: 0.05,
            ..NodeParams::default()
        };
        // As the node hands them over: names resolved (here with no --ros-args).
        let params = params
            .resolved(&crate::ros::resource_names::Names::default())
            .unwrap();
        let mut r = Recorder::new(&params, "truth:spring").unwrap();
        let state = ParticleState {
            dimension: 2,
            ..ParticleState::default()
        };
        let traj = PredictedTrajectory {
            initial: state.clone(),
            steps: 3,
            ..PredictedTrajectory::default()
        };
        r.state(1, &state).unwrap();
        r.prediction(2, &traj, &ParticleForces::default()).unwrap();
        std::thread::sleep(Duration::from_millis(80));
        r.state(3, &state).unwrap();
        r.finish().unwrap();
        assert_eq!(r.finished.len(), 2, "{:?}", r.finished);
        // After `finish` a write opens the next bag; after `close`, none.
        r.state(4, &state).unwrap();
        r.close().unwrap();
        assert_eq!(r.finished.len(), 3, "{:?}", r.finished);
        r.markers(5, &MarkerArray::default()).unwrap();
        r.close().unwrap();
        assert_eq!(r.finished.len(), 3, "{:?}", r.finished);
        let bags = std::fs::read_dir(dir.path().join("rec")).unwrap().count();
        assert_eq!(bags, 3, "no bag opened after close");
        let mut topics = Vec::new();
        scan_bag(&r.finished[0], |m| {
            topics.push(m.topic.to_string());
            Ok(())
        })
        .unwrap();
        assert_eq!(
            topics,
            [
                "/particle_state",
                "/mcgnode/predicted_trajectory",
                "/mcgnode/predicted_forces"
            ]
        );
    }

    /// The metadata record is the typed one, and a model swap reaches both the
    /// open bag and the next ones.
    #[test]
    fn metadata_names_the_current_model_after_a_swap() {
        let dir = tempfile::tempdir().unwrap();
        let params = NodeParams {
            record_dir: dir.path().to_string_lossy().into_owned(),
            ..NodeParams::default()
        };
        let mut r = Recorder::new(&params, "truth:spring").unwrap();
        let state = ParticleState {
            dimension: 2,
            ..ParticleState::default()
        };
        r.state(1, &state).unwrap();
        r.set_model("mcgnode trained on 5-spring").unwrap();
        r.state(2, &state).unwrap();
        r.finish().unwrap();
        r.set_model("gnode v2").unwrap();
        r.state(3, &state).unwrap();
        r.finish().unwrap();
        let meta = |p: &std::path::Path| {
            let mut map = std::collections::BTreeMap::new();
            for (name, m) in scan_bag(p, |_| Ok(())).unwrap() {
                if name == METADATA_NAME {
                    map.extend(m);
                }
            }
            BagMetadata::from_map(&map).unwrap()
        };
        let first = meta(&r.finished[0]);
        assert_eq!(first.model.as_deref(), Some("mcgnode trained on 5-spring"));
        assert_eq!(first.node_dt, Some(params.dt));
        assert_eq!(first.node_horizon, Some(params.horizon));
        assert_eq!(first.recorder.as_deref(), Some("mcgnode serve"));
        assert_eq!(meta(&r.finished[1]).model.as_deref(), Some("gnode v2"));
    }

    #[test]
    fn schemas_carry_their_dependencies() {
        let s = predicted_trajectory_schema();
        assert!(s.starts_with(PREDICTED_TRAJECTORY_MSG));
        for dep in [
            "MSG: std_msgs/Header",
            "MSG: mcgnode_msgs/ParticleState",
            "MSG: geometry_msgs/Point",
        ] {
            assert!(s.contains(dep), "{dep} missing");
        }
        assert!(particle_forces_schema().contains("MSG: geometry_msgs/Vector3"));
    }

    /// A recorder for `dir` finishing chunks after `flush` seconds.
    fn recorder(dir: &Path, flush: f64) -> Recorder {
        let params = NodeParams {
            record_dir: dir.to_string_lossy().into_owned(),
            record_flush_seconds: flush,
            ..NodeParams::default()
        };
        Recorder::new(&params, "truth:spring").unwrap()
    }

    fn state(step: u32) -> ParticleState {
        ParticleState {
            dimension: 2,
            step,
            masses: vec![1.0; 5],
            ..ParticleState::default()
        }
    }

    /// Log times and steps of the states in the file as it is on disk, read
    /// by our reader (every CRC, the footer and the end magic checked).
    fn on_disk(path: &Path) -> Vec<(u64, u32)> {
        let mut got = Vec::new();
        scan_bag(path, |m| {
            if m.schema_name.ends_with("ParticleState") {
                let s = ParticleState::from_cdr(m.data)?;
                got.push((m.log_time, s.step));
            }
            Ok(())
        })
        .unwrap();
        got
    }

    /// With `record_flush_seconds` 0 every message is in the file, and the
    /// file of a killed recorder reads whole, by our reader and by the mcap
    /// crate's strict one (footer and end magic required).
    #[test]
    fn flush_zero_leaves_every_message_readable_after_a_kill() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = recorder(dir.path(), 0.0);
        assert_eq!(r.flush_period(), None);
        for i in 0..40 {
            r.state(1000 + u64::from(i), &state(i)).unwrap();
        }
        let path = r.open.as_ref().unwrap().path.clone();
        std::mem::forget(r); // as SIGKILL: no finish, no Drop
        let got = on_disk(&path);
        assert_eq!(got.len(), 40, "{got:?}");
        assert!(got.iter().enumerate().all(|(i, g)| g.1 == i as u32));
        let bytes = std::fs::read(&path).unwrap();
        let strict = mcap::MessageStream::new(&bytes).unwrap();
        assert_eq!(strict.map(Result::unwrap).count(), 40);
    }

    /// A chunk waits in memory until its oldest message is
    /// `record_flush_seconds` old, as the timer sees it (with its lookahead).
    #[test]
    fn chunks_are_finished_by_age_on_the_timer() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = recorder(dir.path(), 3600.0);
        assert_eq!(r.flush_period(), Some(Duration::from_millis(250)));
        r.flush_due(Instant::now(), Duration::ZERO).unwrap(); // nothing open: no-op
        for i in 0..5 {
            r.state(u64::from(i), &state(i)).unwrap();
        }
        let path = r.open.as_ref().unwrap().path.clone();
        assert!(on_disk(&path).is_empty(), "flushed before its time");
        r.flush_due(Instant::now(), Duration::from_secs(60))
            .unwrap();
        assert!(on_disk(&path).is_empty(), "flushed an hour early");
        r.flush_due(Instant::now(), Duration::from_secs(3600))
            .unwrap();
        assert_eq!(on_disk(&path).len(), 5);
        r.state(5, &state(5)).unwrap();
        assert_eq!(on_disk(&path).len(), 5, "a new chunk waits again");
        r.flush_due(Instant::now() + Duration::from_secs(3600), Duration::ZERO)
            .unwrap();
        assert_eq!(on_disk(&path).len(), 6);
        // Closing writes the summary: the file reads whole, and once.
        r.state(6, &state(6)).unwrap();
        r.close().unwrap();
        assert_eq!(on_disk(&path).len(), 7);
    }

    /// A message logged before the last one written is logged at the last
    /// one's time: a summary-less file is read in file order.
    #[test]
    fn log_times_never_go_back() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = recorder(dir.path(), 0.0);
        r.state(50, &state(0)).unwrap();
        r.state(20, &state(1)).unwrap();
        r.state(70, &state(2)).unwrap();
        let path = r.open.as_ref().unwrap().path.clone();
        r.close().unwrap();
        assert_eq!(on_disk(&path), [(50, 0), (50, 1), (70, 2)]);
    }

    /// A killed node never finishes its bag: with a long `record_flush_seconds`,
    /// everything but the chunk still in memory (≤ 1 MiB) must be readable
    /// from the file as it is.
    #[test]
    fn a_kill_loses_at_most_the_last_chunk() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = recorder(dir.path(), 3600.0);
        let traj = PredictedTrajectory {
            initial: state(0),
            steps: 100,
            positions: vec![0.0; 1000],
            velocities: vec![0.0; 1000],
            ..PredictedTrajectory::default()
        };
        let size = encode_cdr(&traj).unwrap().len();
        // Three and a half 1 MiB chunks: the last one is never complete, whatever
        // the message size.
        let total = (7 << 19) / size;
        let forces = ParticleForces::default();
        for i in 0..total {
            r.prediction(i as u64, &traj, &forces).unwrap();
        }
        let path = r.open.as_ref().unwrap().path.clone();
        std::mem::forget(r); // as SIGKILL: no finish, no Drop
        let bytes = std::fs::read(&path).unwrap();
        let stream = mcap::MessageStream::new(&bytes).unwrap();
        let read = stream
            .map(Result::unwrap)
            .filter(|m| m.channel.topic.ends_with("trajectory"))
            .count();
        let per_chunk = (1 << 20) / size + 1;
        assert!(read > 0 && read < total, "read {read} of {total}");
        assert!(
            read + per_chunk >= total,
            "read {read} of {total}, chunk holds {per_chunk}"
        );
    }
}
