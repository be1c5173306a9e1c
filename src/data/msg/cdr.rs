//! Plain CDR (little- or big-endian) with its 4-byte encapsulation header,
//! for any serde message.

use serde::{de::DeserializeOwned, Serialize};

use crate::data::DataError;

/// The encapsulation header of little-endian plain CDR.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

// `cdr-encoding` needs a `byteorder` type, which is not one of our direct
// dependencies; rustdds (inside ros2-client) re-exports the same functions
// with a representation id instead.
use ros2_client::dds::rustdds::serialization::{
    deserialize_from_cdr_with_rep_id, to_writer_with_rep_id, RepresentationIdentifier,
};

/// Serialises any message to little-endian CDR with the 4-byte encapsulation header.
pub fn encode_cdr<T: Serialize>(msg: &T) -> Result<Vec<u8>, DataError> {
    let mut buf = CDR_LE_HEADER.to_vec();
    to_writer_with_rep_id(&mut buf, msg, RepresentationIdentifier::CDR_LE)
        .map_err(|e| DataError::Cdr(format!("encoding failed: {e}")))?;
    Ok(buf)
}

/// Deserialises CDR bytes with their encapsulation header (little- or big-endian
/// plain CDR). Truncated or garbage input gives an error; at most 3 trailing
/// padding bytes are accepted.
pub fn decode_cdr<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, DataError> {
    if bytes.len() < 4 {
        return Err(DataError::Cdr(format!(
            "{} bytes is too short for the 4-byte encapsulation header",
            bytes.len()
        )));
    }
    let rep = match [bytes[0], bytes[1]] {
        [0x00, 0x01] => RepresentationIdentifier::CDR_LE,
        [0x00, 0x00] => RepresentationIdentifier::CDR_BE,
        other => {
            return Err(DataError::Cdr(format!(
                "encapsulation {:02x} {:02x} is not plain CDR (expected 00 01 or 00 00)",
                other[0], other[1]
            )))
        }
    };
    let body = &bytes[4..];
    let (msg, used) = deserialize_from_cdr_with_rep_id::<T>(body, rep)
        .map_err(|e| DataError::Cdr(format!("decoding {} body bytes failed: {e}", body.len())))?;
    if body.len() - used > 3 {
        return Err(DataError::Cdr(format!(
            "{} bytes left over after the message (schema mismatch?)",
            body.len() - used
        )));
    }
    Ok(msg)
}
