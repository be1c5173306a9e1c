//! Which ParticleState layout a bag's stored schema declares, so that CDR
//! is decoded into the right fields.

use super::scan::RawMessage;
use crate::data::msg::{
    Layout, PARTICLE_STATE_MSG, PARTICLE_STATE_MSG_V1, PARTICLE_STATE_MSG_V2, PARTICLE_STATE_MSG_V3,
};
use crate::data::DataError;

/// The field declarations of a .msg text in order, then its constants sorted,
/// normalised (comments, spacing and `pkg/msg/Type` vs `pkg/Type` do not
/// matter; tools such as rosbags write constants first).
fn declarations(msg: &str) -> Vec<String> {
    let lines: Vec<String> = msg
        .lines()
        .map(|l| l.split('#').next().unwrap_or(""))
        .map(|l| {
            l.split_whitespace()
                .map(|w| w.replace("/msg/", "/"))
                .collect::<Vec<_>>()
                .join(" ")
        })
        .map(|l| l.replace(" = ", "=").replace(" =", "=").replace("= ", "="))
        .filter(|l| !l.is_empty())
        .collect();
    let (mut constants, fields): (Vec<String>, Vec<String>) =
        lines.into_iter().partition(|l| l.contains('='));
    constants.sort();
    let mut out = fields;
    out.push("--".into());
    out.extend(constants);
    out
}

/// Which layout a bag's ParticleState schema declares (otherwise CDR would
/// decode into the wrong fields): this build's, the second (before contacts),
/// the first one, or unknown when the bag stores no definition (old sqlite3
/// bags).
pub(super) fn check_schema(raw: &RawMessage) -> Result<Layout, DataError> {
    if raw.message_encoding != "cdr" {
        return Err(DataError::Invalid(format!(
            "message encoding {:?}, expected \"cdr\"",
            raw.message_encoding
        )));
    }
    if raw.schema_text.is_empty() && raw.schema_encoding.is_empty() {
        return Ok(Layout::Unknown);
    }
    if raw.schema_encoding != "ros2msg" {
        return Err(DataError::Invalid(format!(
            "schema encoding {:?}, expected \"ros2msg\"",
            raw.schema_encoding
        )));
    }
    let text = String::from_utf8_lossy(raw.schema_text);
    let main = text
        .split(&"=".repeat(80))
        .next()
        .unwrap_or_default()
        .to_string();
    let decl = declarations(&main);
    if decl == declarations(PARTICLE_STATE_MSG) {
        Ok(Layout::Current)
    } else if decl == declarations(PARTICLE_STATE_MSG_V3) {
        Ok(Layout::V3)
    } else if decl == declarations(PARTICLE_STATE_MSG_V2) {
        Ok(Layout::V2)
    } else if decl == declarations(PARTICLE_STATE_MSG_V1) {
        Ok(Layout::V1)
    } else {
        Err(DataError::Invalid(
            "its ParticleState schema differs from this build's msg/ParticleState.msg (and from its earlier layouts)".into(),
        ))
    }
}
