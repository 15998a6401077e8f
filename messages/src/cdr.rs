//! The MCAP record of a wire message: a ROS 2 CDR (little-endian, XCDR1) encoding of
//! `header` followed by `Elem[] data`.
//!
//! Because every wire struct is `#[repr(C)]` without padding and every field sits at an offset
//! that is a multiple of its size, the CDR encoding is exactly: the 4-byte encapsulation
//! `00 01 00 00`, the header bytes as they are in shared memory, a `u32` element count, and the
//! payload bytes. A numpy reader therefore needs only fixed offsets:
//! `header = data[4 : 4 + header_size]`, `n = uint32 at 4 + header_size`,
//! `payload = data[8 + header_size :]`.

use crate::types::{MessageType, WireMessage};

/// CDR encapsulation: representation id 0x0001 = CDR little-endian, options 0.
pub const ENCAPSULATION: [u8; 4] = [0, 1, 0, 0];

/// Errors decoding an MCAP record.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum DecodeError {
    #[error("{kind} record too short: {len} bytes, need at least {need}")]
    TooShort { kind: MessageType, len: usize, need: usize },
    #[error("{kind} record has encapsulation {found:?}, expected CDR little-endian {ENCAPSULATION:?}")]
    Encapsulation { kind: MessageType, found: [u8; 4] },
    #[error("{kind} record declares {declared} elements but carries {bytes} payload bytes (element size {elem})")]
    Length { kind: MessageType, declared: usize, bytes: usize, elem: usize },
    #[error("{kind} record: header dimensions imply {expected} elements, payload has {found}")]
    Dimensions { kind: MessageType, expected: usize, found: usize },
}

/// Byte length of the record of a message with `n` elements.
pub fn encoded_len<M: WireMessage>(n: usize) -> usize {
    8 + std::mem::size_of::<M::Header>() + n * std::mem::size_of::<M::Elem>()
}

/// Appends the record of (`header`, `payload`) to `out`.
pub fn encode_into<M: WireMessage>(header: &M::Header, payload: &[M::Elem], out: &mut Vec<u8>) {
    encode_bytes_into(bytemuck::bytes_of(header), payload.len(), bytemuck::cast_slice(payload), out)
}

/// Same as [`encode_into`] from raw header and payload bytes.
pub fn encode_bytes_into(header: &[u8], n_elems: usize, payload: &[u8], out: &mut Vec<u8>) {
    out.reserve(8 + header.len() + payload.len());
    out.extend_from_slice(&ENCAPSULATION);
    out.extend_from_slice(header);
    out.extend_from_slice(&(n_elems as u32).to_le_bytes());
    out.extend_from_slice(payload);
}

/// Splits a record into (header bytes, payload bytes) after checking its structure.
pub fn split(kind: MessageType, data: &[u8]) -> Result<(&[u8], &[u8]), DecodeError> {
    let hs = kind.header_size();
    let es = kind.elem_size();
    let need = 8 + hs;
    if data.len() < need {
        return Err(DecodeError::TooShort { kind, len: data.len(), need });
    }
    let enc = [data[0], data[1], data[2], data[3]];
    if enc != ENCAPSULATION {
        return Err(DecodeError::Encapsulation { kind, found: enc });
    }
    let header = &data[4..4 + hs];
    let n = u32::from_le_bytes([data[4 + hs], data[5 + hs], data[6 + hs], data[7 + hs]]) as usize;
    let payload = &data[need..];
    if n.checked_mul(es) != Some(payload.len()) {
        return Err(DecodeError::Length { kind, declared: n, bytes: payload.len(), elem: es });
    }
    Ok((header, payload))
}

/// Decodes a record into an owned header and payload (copies; the record may be unaligned).
pub fn decode<M: WireMessage>(data: &[u8]) -> Result<(M::Header, Vec<M::Elem>), DecodeError> {
    let (h, p) = split(M::TYPE, data)?;
    let header: M::Header = bytemuck::pod_read_unaligned(h);
    let payload: Vec<M::Elem> = bytemuck::pod_collect_to_vec(p);
    if let Some(expected) = M::expected_len(&header) {
        let eos = M::common(&header).flags & crate::wire::FLAG_END_OF_STREAM != 0;
        if expected != payload.len() && !(eos && payload.is_empty()) {
            return Err(DecodeError::Dimensions { kind: M::TYPE, expected, found: payload.len() });
        }
    }
    Ok((header, payload))
}
