//! PoseArray and PointCloud2 input: the template that says what a tracker
//! cannot (types, masses, graph, kinematic flags, field), read from a bag's
//! first state or a YAML file of ParticleState fields ([`Template`]), and one
//! task per tracker topic that decodes each message ([`super::tracker`]) into
//! a position-only ParticleState of the template and hands it to the input
//! loop, which estimates its velocities with the stream's smoother and
//! predicts it as any other state. Refusals are counted in the diagnostics.

use std::path::Path;
use std::sync::atomic::Ordering;
use std::sync::Arc;

use ros2_client::{Node, Subscription};
use tokio::sync::mpsc::Sender;

use crate::data::msg::{Header, ParticleState, Vector3};
use crate::error::err;

use super::handles::Handles;
use super::params::NodeParams;
use super::qos::{input_qos, subscription};
use super::resource_names::Names;
use super::tracker::{cloud_positions, pose_positions, Expect, TrackerError};
use super::wire::{PointCloud2, PoseArray, RosType};

/// The particles behind tracker input.
#[derive(Clone, Debug, PartialEq)]
pub struct Template {
    /// A position-only state: velocities and accelerations empty.
    msg: ParticleState,
}

impl Template {
    /// `msg` as a template: its positions (zeros when empty) stand in until
    /// the tracker's arrive; its graph must be valid.
    pub fn new(mut msg: ParticleState) -> crate::error::Result<Template> {
        let n = msg.types.len();
        if msg.positions.is_empty() {
            msg.positions = vec![Vector3::default(); n];
        }
        msg.velocities.clear();
        msg.accelerations.clear();
        msg.to_parts_positions_only()
            .map_err(|e| err!("input_template: {e}"))?;
        msg.field().map_err(|e| err!("input_template: {e}"))?;
        Ok(Template { msg })
    }

    /// Reads `path`: a `.yaml`/`.yml` file of ParticleState fields, else a
    /// bag (its first trajectory's first state).
    pub fn load(path: &str) -> crate::error::Result<Template> {
        let p = Path::new(path);
        let yaml = matches!(p.extension().and_then(|e| e.to_str()), Some("yaml" | "yml"));
        let msg = if yaml {
            let text = std::fs::read_to_string(p)
                .map_err(|e| err!("input_template: cannot read {path}: {e}"))?;
            from_yaml(&text).map_err(|e| err!("input_template {path}: {e}"))?
        } else {
            let bag = crate::data::read_trajectories(p)
                .map_err(|e| err!("input_template {path}: {e}"))?;
            let tr = bag.trajectories.first();
            let sample = tr.and_then(|t| t.samples.first());
            let (Some(tr), Some(sample)) = (tr, sample) else {
                return Err(err!("input_template {path}: the bag holds no state"));
            };
            ParticleState::from_sample(tr.id, 0, &tr.system, &tr.graph, sample)
                .with_field(bag.field.as_ref())
        };
        Template::new(msg)
    }

    /// What a tracker message must match, in `frame_id`.
    pub fn expect(&self, frame_id: &str) -> Expect {
        Expect {
            frame_id: frame_id.to_string(),
            n: self.msg.types.len(),
            dim: usize::from(self.msg.dimension),
        }
    }

    /// The template at `positions` (taken), stamped and framed by `header`.
    pub fn state(
        &self,
        header: &Header,
        positions: &mut Vec<Vector3>,
        id: u32,
        step: u32,
    ) -> ParticleState {
        let mut m = self.msg.clone();
        m.header = header.clone();
        m.trajectory_id = id;
        m.step = step;
        m.positions = std::mem::take(positions);
        m
    }

    /// The trajectory id of the template's stream.
    pub fn trajectory_id(&self) -> u32 {
        self.msg.trajectory_id
    }
}

/// A ParticleState from YAML: a mapping of its fields (those left out keep
/// their defaults; `positions` may be left out).
fn from_yaml(text: &str) -> crate::error::Result<ParticleState> {
    let docs = yaml_rust2::YamlLoader::load_from_str(text).map_err(|e| err!("{e}"))?;
    let [doc] = docs.as_slice() else {
        return Err(err!("{} YAML documents; expected one mapping", docs.len()));
    };
    let mut base = serde_json::to_value(ParticleState::default()).map_err(|e| err!("{e}"))?;
    let (Some(fields), yaml_rust2::Yaml::Hash(given)) = (base.as_object_mut(), doc) else {
        return Err(err!("expected a mapping of ParticleState fields"));
    };
    for (k, v) in given {
        let key = k.as_str().ok_or_else(|| err!("a key is not a string"))?;
        if !fields.contains_key(key) {
            let known: Vec<&str> = fields.keys().map(String::as_str).collect();
            return Err(err!(
                "unknown field {key:?}; ParticleState has {}",
                known.join(", ")
            ));
        }
        let value = json(v).map_err(|e| err!("{key}: {e}"))?;
        fields.insert(key.to_string(), value);
    }
    serde_json::from_value(base).map_err(|e| err!("{e}"))
}

/// A YAML value as JSON.
fn json(y: &yaml_rust2::Yaml) -> crate::error::Result<serde_json::Value> {
    use serde_json::Value as J;
    use yaml_rust2::Yaml as Y;
    Ok(match y {
        Y::Integer(i) => J::from(*i),
        Y::Real(r) => J::from(r.parse::<f64>().map_err(|e| err!("{r}: {e}"))?),
        Y::String(s) => J::from(s.as_str()),
        Y::Boolean(b) => J::from(*b),
        Y::Array(xs) => J::Array(xs.iter().map(json).collect::<crate::error::Result<_>>()?),
        Y::Hash(h) => {
            let mut m = serde_json::Map::new();
            for (k, v) in h {
                let key = k.as_str().ok_or_else(|| err!("a key is not a string"))?;
                m.insert(key.to_string(), json(v)?);
            }
            J::Object(m)
        }
        Y::Null => J::Null,
        other => return Err(err!("unsupported YAML value {other:?}")),
    })
}

/// The tracker subscriptions the parameters ask for, with their template.
pub(super) struct TrackerInputs {
    template: Arc<Template>,
    poses: Option<Subscription<PoseArray>>,
    cloud: Option<Subscription<PointCloud2>>,
}

impl TrackerInputs {
    /// `None` when neither `pose_array_topic` nor `point_cloud_topic` is set;
    /// else the template (refused with the reason) and the subscriptions.
    pub(super) fn create(
        node: &mut Node,
        params: &NodeParams,
        names: &Names,
    ) -> crate::error::Result<Option<TrackerInputs>> {
        let (pose_topic, cloud_topic) = (&params.pose_array_topic, &params.point_cloud_topic);
        if pose_topic.is_empty() && cloud_topic.is_empty() {
            return Ok(None);
        }
        if params.input_template.is_empty() {
            return Err(err!(
                "pose_array_topic and point_cloud_topic need input_template: a bag or a .yaml \
                 file of ParticleState fields giving types, masses and the graph"
            ));
        }
        let template = Arc::new(Template::load(&params.input_template)?);
        let qos = input_qos(params);
        let poses = (!pose_topic.is_empty())
            .then(|| subscription(node, names, pose_topic, &qos))
            .transpose()?;
        let cloud = (!cloud_topic.is_empty())
            .then(|| subscription(node, names, cloud_topic, &qos))
            .transpose()?;
        Ok(Some(TrackerInputs {
            template,
            poses,
            cloud,
        }))
    }

    /// One task per subscription, sending its states to `tx`: PoseArray
    /// states on the template's trajectory id, PointCloud2 on the next.
    pub(super) fn spawn(self, h: &Handles, tx: &Sender<ParticleState>) {
        let id = self.template.trajectory_id();
        if let Some(sub) = self.poses {
            let t = Source::new(h, &self.template, tx, id);
            tokio::spawn(tracker_loop(t, sub, pose_positions));
        }
        if let Some(sub) = self.cloud {
            let t = Source::new(h, &self.template, tx, id.wrapping_add(1));
            tokio::spawn(tracker_loop(t, sub, cloud_positions));
        }
    }
}

/// What one tracker task needs.
struct Source {
    h: Handles,
    template: Arc<Template>,
    tx: Sender<ParticleState>,
    id: u32,
}

impl Source {
    fn new(h: &Handles, template: &Arc<Template>, tx: &Sender<ParticleState>, id: u32) -> Source {
        Source {
            h: h.clone(),
            template: Arc::clone(template),
            tx: tx.clone(),
            id,
        }
    }
}

/// A decoder of tracker messages of type `M`.
type Decode<M> = fn(&M, &Expect, &mut Vec<Vector3>) -> Result<(), TrackerError>;

/// A tracker message's header.
trait Stamped {
    fn header(&self) -> &Header;
}
impl Stamped for PoseArray {
    fn header(&self) -> &Header {
        &self.header
    }
}
impl Stamped for PointCloud2 {
    fn header(&self) -> &Header {
        &self.header
    }
}

/// Takes each message of `sub`, decodes it (refusals counted and warned
/// about) and sends the template's state at its positions to the input loop.
async fn tracker_loop<M: RosType + Stamped>(s: Source, sub: Subscription<M>, decode: Decode<M>) {
    let stats = &s.h.diag.stats;
    let mut positions = Vec::new();
    let mut step = 0u32;
    loop {
        let taken = sub.async_take().await;
        stats.received.fetch_add(1, Ordering::Relaxed);
        let msg = match taken {
            Ok((msg, _)) => msg,
            Err(e) => {
                s.h.diag.reject(&format!("undecodable {}: {e:?}", M::NAME));
                continue;
            }
        };
        let expect = s.template.expect(&s.h.params.get().frame_id);
        if let Err(why) = decode(&msg, &expect, &mut positions) {
            s.h.diag.reject(&format!("rejected input: {why}"));
            continue;
        }
        let state = s.template.state(msg.header(), &mut positions, s.id, step);
        step = step.wrapping_add(1);
        if s.tx.send(state).await.is_err() {
            // The input loop has ended: the node is shutting down.
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RING: &str = "dimension: 2\ntypes: [0, 0, 0]\nmasses: [1, 1.0, 2]\nedge_a: [0, 1, 2]\n\
                        edge_b: [1, 2, 0]\nedge_kind: [0, 0, 0]\nedge_rest_length: [1, 1, 1]\n\
                        edge_stiffness: [1, 1, 1]\ntrajectory_id: 4\n";

    #[test]
    fn a_yaml_template_gives_the_graph_and_tracker_positions_fill_it() {
        let t = Template::new(from_yaml(RING).unwrap()).unwrap();
        assert_eq!(
            t.expect("map"),
            Expect {
                frame_id: "map".into(),
                n: 3,
                dim: 2
            }
        );
        assert_eq!(t.trajectory_id(), 4);
        let header = Header {
            frame_id: "map".into(),
            ..Header::default()
        };
        let mut pos = vec![
            Vector3 {
                x: 1.0,
                y: 2.0,
                z: 0.0
            };
            3
        ];
        let s = t.state(&header, &mut pos, 9, 5);
        assert!(pos.is_empty());
        assert_eq!((s.trajectory_id, s.step, s.masses[2]), (9, 5, 2.0));
        assert_eq!(s.positions[1].y, 2.0);
        assert!(s.velocities.is_empty());
        let (graph, _, no_v) = s.to_parts_positions_only().unwrap();
        assert!(no_v);
        assert_eq!(graph.n(), 3);
    }

    /// The template of docs/ros.md, as a file.
    #[test]
    fn the_documented_yaml_template_loads() {
        let doc = include_str!("../../docs/ros.md");
        let start = doc
            .find("```yaml\ndimension")
            .expect("the template in docs/ros.md")
            + 8;
        let yaml = &doc[start..start + doc[start..].find("```").expect("its end")];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ring.yaml");
        std::fs::write(&path, yaml).unwrap();
        let t = Template::load(path.to_str().unwrap()).unwrap();
        assert_eq!(t.expect("world").n, 3);
        // Tracker topics without a template are refused before the node starts.
        let p = NodeParams {
            pose_array_topic: "/tracker/poses".into(),
            ..NodeParams::default()
        };
        let e = p.check_together().unwrap_err().to_string();
        assert!(e.contains("need input_template"), "{e}");
    }

    #[test]
    fn bad_templates_are_refused_with_the_reason() {
        let e = from_yaml("typs: [0]\n").unwrap_err().to_string();
        assert!(
            e.contains("unknown field \"typs\"") && e.contains("types"),
            "{e}"
        );
        let e = from_yaml("- 1\n").unwrap_err().to_string();
        assert!(e.contains("mapping"), "{e}");
        let e = from_yaml("masses: [a]\n").unwrap_err().to_string();
        assert!(e.contains("invalid type"), "{e}");
        let short = RING.replace("masses: [1, 1.0, 2]", "masses: [1, 1]");
        let e = Template::new(from_yaml(&short).unwrap())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("input_template") && e.contains("masses has 2 entries"),
            "{e}"
        );
        let e = Template::load("/nonexistent/t.yaml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("cannot read /nonexistent/t.yaml"), "{e}");
    }
}
