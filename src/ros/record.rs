//! Recording what the node sees and says to MCAP bags (the ROS 2 convention,
//! readable by mcap-ros2-support and rosbags): incoming states, predicted
//! trajectories and forces, each on its topic with its full schema.
//!
//! Bags are written straight to an unbuffered file, so every finished chunk is
//! on disk: a SIGKILL loses at most the chunk in memory (≤ 1 MiB of messages).
//! Bags split by size or duration; [`Recorder::finish`] closes the open one.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

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

/// One open bag and its channels.
struct OpenBag {
    writer: BagWriter<File>,
    path: PathBuf,
    file: File,
    opened: Instant,
    /// States, trajectories, forces, markers (the order of `Recorder::topics`).
    channels: [ChannelId; 4],
}

/// Writes the node's traffic to a sequence of bags in one folder.
pub struct Recorder {
    dir: PathBuf,
    topics: [String; 4],
    split_bytes: u64,
    split_after: Option<Duration>,
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
        // Unbuffered on purpose: finished chunks reach the file at once.
        let handle = file.try_clone().map_err(|e| ctx(e.into()))?;
        let mut writer = BagWriter::new(file).map_err(|e| ctx(e.into()))?;
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
        Ok(self.open.insert(OpenBag {
            writer,
            path,
            file: handle,
            opened: Instant::now(),
            channels,
        }))
    }

    /// Closes the open bag if it reached its size or duration limit.
    fn maybe_split(&mut self) -> Result<(), RecordError> {
        let Some(bag) = &self.open else {
            return Ok(());
        };
        let size = bag.file.metadata().map(|m| m.len()).unwrap_or(0);
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
            })
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
            bag.writer
                .add_metadata(METADATA_NAME, &map)
                .map_err(write)?;
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

    /// A killed node never finishes its bag: everything but the chunk still in
    /// memory must be readable from the file as it is.
    #[test]
    fn a_kill_loses_at_most_the_last_chunk() {
        let dir = tempfile::tempdir().unwrap();
        let params = NodeParams {
            record_dir: dir.path().to_string_lossy().into_owned(),
            ..NodeParams::default()
        };
        let mut r = Recorder::new(&params, "truth:spring").unwrap();
        let state = ParticleState {
            dimension: 2,
            masses: vec![1.0; 5],
            ..ParticleState::default()
        };
        let traj = PredictedTrajectory {
            initial: state,
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
        let stream = mcap::MessageStream::new_with_options(
            &bytes,
            mcap::read::Options::IgnoreEndMagic.into(),
        )
        .unwrap();
        let read = stream
            .take_while(Result::is_ok)
            .filter(|m| {
                m.as_ref()
                    .is_ok_and(|m| m.channel.topic.ends_with("trajectory"))
            })
            .count();
        let per_chunk = (1 << 20) / size + 1;
        assert!(read > 0 && read < total, "read {read} of {total}");
        assert!(
            read + per_chunk >= total,
            "read {read} of {total}, chunk holds {per_chunk}"
        );
    }
}
