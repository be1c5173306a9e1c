//! TFRecord files: each record is a little-endian u64 length, the masked
//! CRC-32C of those 8 bytes, the data, and the masked CRC-32C of the data.
//! Both checksums are verified.

/// What is wrong with a record or its contents, in words; the caller adds
/// the file ([`crate::data::DataError::Import`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct Damage(pub String);

impl From<String> for Damage {
    fn from(s: String) -> Self {
        Damage(s)
    }
}

impl From<&str> for Damage {
    fn from(s: &str) -> Self {
        Damage(s.to_string())
    }
}

/// TensorFlow's CRC mask.
const MASK_DELTA: u32 = 0xa282_ead8;

/// The masked CRC-32C of `data`, as TFRecord stores it.
pub fn masked_crc(data: &[u8]) -> u32 {
    let crc = crc32c::crc32c(data);
    crc.rotate_right(15).wrapping_add(MASK_DELTA)
}

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    let mut b = [0u8; 4];
    b.copy_from_slice(&bytes[at..at + 4]);
    u32::from_le_bytes(b)
}

/// The records of a TFRecord file, in order. The error says which record,
/// at which byte offset, and what is wrong (truncated, bad checksum).
pub fn records(bytes: &[u8]) -> Result<Vec<&[u8]>, Damage> {
    let mut out = Vec::new();
    let mut at = 0usize;
    while at < bytes.len() {
        let k = out.len();
        let rest = bytes.len() - at;
        if rest < 12 {
            return Err(Damage(format!(
                "record {k} at byte {at}: truncated header ({rest} of 12 bytes)"
            )));
        }
        let len_bytes = &bytes[at..at + 8];
        if u32_at(bytes, at + 8) != masked_crc(len_bytes) {
            return Err(Damage(format!(
                "record {k} at byte {at}: the length's CRC does not match (corrupt file)"
            )));
        }
        let mut lb = [0u8; 8];
        lb.copy_from_slice(len_bytes);
        let len = u64::from_le_bytes(lb);
        let body = at + 12;
        let avail = (bytes.len() - body) as u64;
        if len > avail.saturating_sub(4) {
            return Err(Damage(format!(
                "record {k} at byte {at}: truncated: {len} data bytes and a 4-byte CRC \
                 announced, {avail} bytes left"
            )));
        }
        let len = len as usize;
        let data = &bytes[body..body + len];
        if u32_at(bytes, body + len) != masked_crc(data) {
            return Err(Damage(format!(
                "record {k} at byte {at}: the data's CRC does not match (corrupt file)"
            )));
        }
        out.push(data);
        at = body + len + 4;
    }
    Ok(out)
}

/// Frames `data` as one TFRecord record (for writing test files).
pub fn frame(data: &[u8]) -> Vec<u8> {
    let len = (data.len() as u64).to_le_bytes();
    let mut out = Vec::with_capacity(data.len() + 16);
    out.extend_from_slice(&len);
    out.extend_from_slice(&masked_crc(&len).to_le_bytes());
    out.extend_from_slice(data);
    out.extend_from_slice(&masked_crc(data).to_le_bytes());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_read_back_and_damage_is_named() {
        let mut file = frame(b"hello");
        file.extend(frame(b""));
        file.extend(frame(&[7u8; 300]));
        let r = records(&file).unwrap();
        assert_eq!(r, vec![&b"hello"[..], &b""[..], &[7u8; 300][..]]);
        let mut bad = file.clone();
        bad[13] ^= 1;
        assert!(records(&bad).unwrap_err().0.contains("data's CRC"));
        let cut = &file[..file.len() - 3];
        assert!(records(cut).unwrap_err().0.contains("record 2"));
    }

    #[test]
    fn known_crc32c() {
        // CRC-32C of "123456789" is 0xe3069283 (RFC 3720's check value).
        assert_eq!(crc32c::crc32c(b"123456789"), 0xe306_9283);
    }
}
