//! Network weights in the safetensors format (<https://github.com/huggingface/safetensors>),
//! read and written with the format's reference crate `safetensors`:
//!
//! - 8 bytes: N, the header length, u64 little-endian;
//! - N bytes: a UTF-8 JSON object `{name: {"dtype": "F32"|"F64", "shape": [...], "data_offsets":
//!   [begin, end]}, …, "__metadata__": {string: string}}`, padded with spaces to a multiple of 8;
//! - the data: each tensor's values little-endian, row-major, at `begin..end` of the bytes after
//!   the header; the tensors tile that buffer with no gap and no overlap.
//!
//! [`read_bytes`] lets the crate check all of that, accepts F32 and F64 tensors and never panics on
//! a bad file; its errors name the file and, where one tensor is at fault, the tensor (which the
//! crate's errors do not always do). [`write_bytes`] stores the tensors by descending dtype, then by
//! name (the crate's order; all F64 for a network, so by name); the header's entries come in the
//! crate's order (`__metadata__` in hash-map order), so two writes of one network may differ in the
//! header's bytes, never in its entries or in the data. The shipped `weights/*.safetensors` were
//! written by this module's earlier hand-written writer (sorted keys) and load to the same values
//! (test `shipped_weights_load_to_the_values_the_hand_written_reader_gave`). An [`Mlp`] is stored as
//! `layers.{l}.weight` (shape \[n_{l+1}, n_l\], PyTorch's `Linear` layout), `layers.{l}.bias`,
//! `input.mean`, `input.std`, `output.mean`, `output.scale` (F64, so a round trip is exact; F32
//! files, e.g. from PyTorch, load too) and the metadata `format` = `sonoflow-mlp`, `version` =
//! `1`, `sizes` (e.g. `6,50,20,20,3`), `activation` = `relu`, for a mirror-averaged network
//! `mirror` (the [`super::mlp::Mirror`] as JSON, e.g. `{"swap":[[3,4]],"reflect":[[5,6.283185307179586]],"negate":[2]}`),
//! plus any caller entries.

use super::mlp::Mlp;
use super::NnError;
use safetensors::tensor::{SafeTensorError, SafeTensors, TensorInfo, TensorView};
use std::collections::BTreeMap;
use std::path::Path;

/// Element type of a stored tensor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dtype {
    /// 32-bit IEEE float.
    F32,
    /// 64-bit IEEE float.
    F64,
}

impl From<Dtype> for safetensors::Dtype {
    fn from(d: Dtype) -> Self {
        match d {
            Dtype::F32 => safetensors::Dtype::F32,
            Dtype::F64 => safetensors::Dtype::F64,
        }
    }
}

impl TryFrom<safetensors::Dtype> for Dtype {
    type Error = String;
    fn try_from(d: safetensors::Dtype) -> Result<Self, String> {
        match d {
            safetensors::Dtype::F32 => Ok(Dtype::F32),
            safetensors::Dtype::F64 => Ok(Dtype::F64),
            other => Err(format!("dtype `{other}` is not supported: allowed F32, F64")),
        }
    }
}

/// A tensor: shape, element type on disk, values (as f64 in memory).
#[derive(Clone, Debug, PartialEq)]
pub struct Tensor {
    /// Dimensions, row-major.
    pub shape: Vec<usize>,
    /// Element type on disk.
    pub dtype: Dtype,
    /// Values, row-major; length = product of `shape`.
    pub data: Vec<f64>,
}

/// The tensors of a file by name, and its metadata.
pub type TensorFile = (BTreeMap<String, Tensor>, BTreeMap<String, String>);

/// The safetensors bytes of `tensors` and `metadata` (the crate's layout: module doc).
pub fn write_bytes(
    tensors: &BTreeMap<String, Tensor>,
    metadata: &BTreeMap<String, String>,
) -> Result<Vec<u8>, NnError> {
    let tensor_err =
        |tensor: &str, reason: String| NnError::Tensor { path: "<memory>".into(), tensor: tensor.into(), reason };
    let mut encoded = Vec::with_capacity(tensors.len());
    for (name, t) in tensors {
        let numel = t.shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
        if numel != Some(t.data.len()) || name == "__metadata__" {
            return Err(tensor_err(
                name,
                format!("shape {:?} holds {numel:?} values, data has {} (or a reserved name)", t.shape, t.data.len()),
            ));
        }
        let bytes: Vec<u8> = match t.dtype {
            Dtype::F32 => t.data.iter().flat_map(|&v| (v as f32).to_le_bytes()).collect(),
            Dtype::F64 => t.data.iter().flat_map(|&v| v.to_le_bytes()).collect(),
        };
        encoded.push((name.as_str(), t, bytes));
    }
    let views = encoded
        .iter()
        .map(|(name, t, bytes)| {
            TensorView::new(t.dtype.into(), t.shape.clone(), bytes)
                .map(|view| (*name, view))
                .map_err(|e| tensor_err(name, e.to_string()))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let metadata = (!metadata.is_empty()).then(|| metadata.iter().map(|(k, v)| (k.clone(), v.clone())).collect());
    safetensors::serialize(views, metadata)
        .map_err(|e| NnError::Format { path: "<memory>".into(), reason: format!("safetensors: {e}") })
}

/// Parses and validates safetensors `bytes` (`path` names the file in errors).
pub fn read_bytes(bytes: &[u8], path: &str) -> Result<TensorFile, NnError> {
    let tensor_err =
        |tensor: &str, reason: String| NnError::Tensor { path: path.into(), tensor: tensor.into(), reason };
    // safetensors 0.8.0's `read_metadata` adds the end of the declared data to the header length
    // unchecked (tensor.rs:420): with overflow checks on (debug builds) a crafted header whose data
    // ends near 2^64 bytes panics there. Such a header declares more data than the file has, which
    // is refused here first.
    if let Some((entries, data)) = header_entries(bytes) {
        if let Some((name, info)) = entries.iter().find(|(_, info)| info.data_offsets.1 > data) {
            let (begin, end) = info.data_offsets;
            return Err(tensor_err(name, format!("data_offsets [{begin}, {end}] outside the {data} data bytes")));
        }
    }
    let (n, header) = SafeTensors::read_metadata(bytes).map_err(|e| explain(bytes, path, e))?;
    // read_metadata checked that the header and every tensor's data_offsets lie in the file
    let data = bytes.get(8 + n..).unwrap_or_default();
    let mut tensors = BTreeMap::new();
    for (name, info) in header.tensors() {
        let dtype = Dtype::try_from(info.dtype).map_err(|reason| tensor_err(&name, reason))?;
        let (begin, end) = info.data_offsets;
        let raw = data.get(begin..end).ok_or_else(|| {
            tensor_err(&name, format!("data_offsets [{begin}, {end}] outside the {} data bytes", data.len()))
        })?;
        let values = match dtype {
            Dtype::F32 => raw.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64).collect(),
            Dtype::F64 => raw
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
                .collect(),
        };
        tensors.insert(name, Tensor { shape: info.shape.clone(), dtype, data: values });
    }
    let metadata = header.metadata().iter().flatten().map(|(k, v)| (k.clone(), v.clone())).collect();
    Ok((tensors, metadata))
}

/// The tensor entries of the header of `bytes` (those that parse as the crate's [`TensorInfo`])
/// sorted by offsets, and the number of data bytes after the header; None if the length or the
/// header do not parse. For the checks and error messages around the crate's reader.
fn header_entries(bytes: &[u8]) -> Option<(Vec<(String, TensorInfo)>, usize)> {
    let n = usize::try_from(u64::from_le_bytes(bytes.get(..8)?.try_into().ok()?)).ok()?;
    let header = bytes.get(8..8usize.checked_add(n)?)?;
    let mut map: BTreeMap<String, serde_json::Value> = serde_json::from_slice(header).ok()?;
    map.remove("__metadata__");
    let mut list: Vec<(String, TensorInfo)> =
        map.into_iter().filter_map(|(k, v)| Some((k, serde_json::from_value(v).ok()?))).collect();
    list.sort_by_key(|(_, info)| info.data_offsets);
    Some((list, bytes.len() - 8 - n))
}

/// A [`NnError`] for the crate's error `e` on `bytes`, naming the tensor at fault where the crate
/// does not (then the header's entries are looked at again, in offset order).
fn explain(bytes: &[u8], path: &str, e: SafeTensorError) -> NnError {
    let format = |reason: String| NnError::Format { path: path.into(), reason };
    let tensor_err =
        |tensor: &str, reason: String| NnError::Tensor { path: path.into(), tensor: tensor.into(), reason };
    let n = bytes.get(..8).and_then(|b| b.try_into().ok()).map(u64::from_le_bytes).unwrap_or(0);
    let available = bytes.len().saturating_sub(8);
    // bytes of a tensor, None on overflow
    let size = |info: &TensorInfo| {
        info.shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d))?.checked_mul(info.dtype.bitsize()).map(|b| b / 8)
    };
    let found = match &e {
        SafeTensorError::HeaderTooSmall => {
            return format(format!("{} bytes: shorter than the 8-byte header length", bytes.len()))
        }
        SafeTensorError::HeaderTooLarge | SafeTensorError::InvalidHeaderLength => {
            return format(format!(
                "header length {n} exceeds the file ({available} bytes after the length) or the format's limit of 100 000 000"
            ))
        }
        SafeTensorError::InvalidHeader(u) => return format(format!("header is not UTF-8: {u}")),
        SafeTensorError::InvalidHeaderDeserialization(j) => {
            return format(format!("header is not valid JSON for safetensors: {j}"))
        }
        SafeTensorError::InvalidOffset(name) => header_entries(bytes).and_then(|(list, _)| {
            let i = list.iter().position(|(k, _)| k == name)?;
            let at = if i == 0 { 0 } else { list[i - 1].1.data_offsets.1 };
            let (begin, end) = list[i].1.data_offsets;
            Some(tensor_err(
                name,
                format!(
                    "data_offsets [{begin}, {end}], expected to start at byte {at}: the tensors must tile the data without gaps or overlaps"
                ),
            ))
        }),
        SafeTensorError::TensorInvalidInfo | SafeTensorError::ValidationOverflow => header_entries(bytes).and_then(|(list, _)| {
            list.iter().find_map(|(name, info)| {
                let (begin, end) = info.data_offsets;
                // an unsupported dtype first: its size is the likely cause of the mismatch
                if let Err(reason) = Dtype::try_from(info.dtype) {
                    return Some(tensor_err(name, reason));
                }
                let reason = match size(info) {
                    None => format!("shape {:?} of {} overflows", info.shape, info.dtype),
                    Some(s) if end.checked_sub(begin) != Some(s) => format!(
                        "shape {:?} of {} needs {s} bytes, data_offsets [{begin}, {end}] give {}",
                        info.shape,
                        info.dtype,
                        end.saturating_sub(begin)
                    ),
                    Some(_) => return None,
                };
                Some(tensor_err(name, reason))
            })
        }),
        // (data beyond the file is refused before the crate reads: [`read_bytes`])
        SafeTensorError::MetadataIncompleteBuffer => header_entries(bytes).map(|(list, data)| {
            let end = list.last().map_or(0, |(_, info)| info.data_offsets.1);
            format(format!("{} trailing data bytes after the last tensor", data.saturating_sub(end)))
        }),
        _ => None,
    };
    found.unwrap_or_else(|| format(format!("safetensors: {e}")))
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> NnError + '_ {
    move |source| NnError::Io { path: path.display().to_string(), source }
}

impl Mlp {
    /// The tensors and metadata of this network (module doc); `extra` metadata entries are added
    /// (they may not replace the reserved keys).
    pub fn to_tensors(&self, extra: &[(&str, &str)]) -> Result<TensorFile, NnError> {
        let mut t = BTreeMap::new();
        let f64t = |shape: Vec<usize>, data: &[f64]| Tensor { shape, dtype: Dtype::F64, data: data.to_vec() };
        for l in 0..self.n_layers() {
            let (n_in, n_out) = (self.sizes()[l], self.sizes()[l + 1]);
            t.insert(format!("layers.{l}.weight"), f64t(vec![n_out, n_in], self.weights(l)));
            t.insert(format!("layers.{l}.bias"), f64t(vec![n_out], self.biases(l)));
        }
        t.insert("input.mean".into(), f64t(vec![self.n_inputs()], self.input_mean()));
        t.insert("input.std".into(), f64t(vec![self.n_inputs()], self.input_std()));
        t.insert("output.mean".into(), f64t(vec![self.n_outputs()], self.output_mean()));
        t.insert("output.scale".into(), f64t(vec![self.n_outputs()], self.output_scale()));
        let mut m = BTreeMap::new();
        for (k, v) in extra {
            m.insert(k.to_string(), v.to_string());
        }
        let sizes: Vec<String> = self.sizes().iter().map(ToString::to_string).collect();
        let mirror = match self.mirror() {
            Some(mr) => serde_json::to_string(mr).map_err(|e| NnError::Config {
                field: "mirror",
                value: e.to_string(),
                allowed: "a serialisable mirror",
            })?,
            None => String::new(),
        };
        // "mirror" is reserved whether or not this network has one
        let reserved = [
            ("format", "sonoflow-mlp".to_string()),
            ("version", "1".to_string()),
            ("activation", "relu".to_string()),
            ("sizes", sizes.join(",")),
            ("mirror", mirror),
        ];
        for (k, v) in reserved {
            if m.insert(k.to_string(), v).is_some() {
                return Err(NnError::Config {
                    field: "metadata",
                    value: k.to_string(),
                    allowed: "keys other than format, version, activation, sizes, mirror",
                });
            }
        }
        if self.mirror().is_none() {
            m.remove("mirror");
        }
        Ok((t, m))
    }

    /// A network from tensors and metadata as [`Mlp::to_tensors`] writes them; `path` names the
    /// file in errors. Checks the format, the sizes, every tensor's shape, no missing or extra
    /// tensor, finite values, σ > 0 and s ≠ 0.
    pub fn from_tensors(
        tensors: &BTreeMap<String, Tensor>,
        metadata: &BTreeMap<String, String>,
        path: &str,
    ) -> Result<Mlp, NnError> {
        let format = |reason: String| NnError::Format { path: path.into(), reason };
        let meta = |k: &str| metadata.get(k).map(String::as_str);
        if meta("format") != Some("sonoflow-mlp") || meta("version") != Some("1") {
            return Err(format(format!(
                "metadata format/version = {:?}/{:?}, expected sonoflow-mlp/1",
                meta("format"),
                meta("version")
            )));
        }
        if meta("activation") != Some("relu") {
            return Err(format(format!("metadata activation = {:?}, expected relu", meta("activation"))));
        }
        let sizes_s = meta("sizes").ok_or_else(|| format("no metadata `sizes`".into()))?;
        let sizes: Vec<usize> = sizes_s
            .split(',')
            .map(|s| s.trim().parse::<usize>())
            .collect::<Result<_, _>>()
            .map_err(|e| format(format!("metadata sizes = `{sizes_s}`: {e}")))?;
        if sizes.len() < 2 || sizes.iter().any(|&n| n == 0 || n > 4096) {
            return Err(format(format!("metadata sizes = `{sizes_s}`: need >= 2 sizes in 1..=4096")));
        }
        let mut used = std::collections::BTreeSet::new();
        let mut get = |name: String, shape: Vec<usize>| -> Result<Vec<f64>, NnError> {
            let t = tensors.get(&name).ok_or_else(|| NnError::Tensor {
                path: path.into(),
                tensor: name.clone(),
                reason: format!("missing (sizes {sizes_s})"),
            })?;
            if t.shape != shape {
                return Err(NnError::Tensor {
                    path: path.into(),
                    tensor: name,
                    reason: format!("shape {:?}, expected {shape:?} for sizes {sizes_s}", t.shape),
                });
            }
            if let Some(i) = t.data.iter().position(|v| !v.is_finite()) {
                return Err(NnError::Tensor {
                    path: path.into(),
                    tensor: name,
                    reason: format!("value {} at index {i} is not finite", t.data[i]),
                });
            }
            used.insert(name);
            Ok(t.data.clone())
        };
        let layers = sizes.len() - 1;
        let mut w = Vec::with_capacity(layers);
        let mut b = Vec::with_capacity(layers);
        for l in 0..layers {
            w.push(get(format!("layers.{l}.weight"), vec![sizes[l + 1], sizes[l]])?);
            b.push(get(format!("layers.{l}.bias"), vec![sizes[l + 1]])?);
        }
        let (n_in, n_out) = (sizes[0], sizes[layers]);
        let im = get("input.mean".into(), vec![n_in])?;
        let is = get("input.std".into(), vec![n_in])?;
        let om = get("output.mean".into(), vec![n_out])?;
        let os = get("output.scale".into(), vec![n_out])?;
        let extra: Vec<&String> = tensors.keys().filter(|k| !used.contains(*k)).collect();
        if !extra.is_empty() {
            return Err(format(format!("unexpected tensors {extra:?} for sizes {sizes_s}")));
        }
        let mirror = match meta("mirror") {
            Some(text) => Some(
                serde_json::from_str::<super::mlp::Mirror>(text)
                    .map_err(|e| format(format!("metadata mirror = `{text}`: {e}")))?,
            ),
            None => None,
        };
        Mlp::from_parts(sizes, w, b, im, is, om, os)
            .and_then(|net| net.with_mirror(mirror))
            .map_err(|e| format(e.to_string()))
    }

    /// Writes the network to a safetensors file with `extra` metadata.
    pub fn save(&self, path: &Path, extra: &[(&str, &str)]) -> Result<(), NnError> {
        let (t, m) = self.to_tensors(extra)?;
        std::fs::write(path, write_bytes(&t, &m)?).map_err(io(path))
    }

    /// Reads a network from a safetensors file; returns it with the file's metadata.
    pub fn load(path: &Path) -> Result<(Mlp, BTreeMap<String, String>), NnError> {
        let bytes = std::fs::read(path).map_err(io(path))?;
        let name = path.display().to_string();
        let (t, m) = read_bytes(&bytes, &name)?;
        Ok((Mlp::from_tensors(&t, &m, &name)?, m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn net() -> Mlp {
        Mlp::he_init(&[5, 20, 20, 20, 1], 4)
            .and_then(|m| {
                m.with_normalisation(
                    vec![3.0, 0.5, 3.0, 1.0, 1.0],
                    vec![0.3, 0.2, 0.3, 0.4, 0.4],
                    vec![1.5],
                    vec![0.25],
                )
            })
            .expect("valid")
    }

    fn bytes() -> Vec<u8> {
        let (t, m) = net().to_tensors(&[("outputs", "t_r")]).expect("valid");
        write_bytes(&t, &m).expect("valid")
    }

    fn load(b: &[u8]) -> Result<Mlp, NnError> {
        let (t, m) = read_bytes(b, "test.safetensors")?;
        Mlp::from_tensors(&t, &m, "test.safetensors")
    }

    /// Header length and the header text of `b`.
    fn header(b: &[u8]) -> String {
        let n = u64::from_le_bytes(b[..8].try_into().expect("8 bytes")) as usize;
        String::from_utf8(b[8..8 + n].to_vec()).expect("utf-8")
    }

    /// `b` with its header replaced by `h` (padded to 8).
    fn with_header(b: &[u8], h: &str) -> Vec<u8> {
        let n = u64::from_le_bytes(b[..8].try_into().expect("8 bytes")) as usize;
        let mut h = h.as_bytes().to_vec();
        h.resize(h.len() + (8 - h.len() % 8) % 8, b' ');
        let mut out = (h.len() as u64).to_le_bytes().to_vec();
        out.extend_from_slice(&h);
        out.extend_from_slice(&b[8 + n..]);
        out
    }

    /// FNV-1a (64 bit) over every tensor (name order: name, dtype, shape, the f64 bits of each
    /// value) and every metadata entry of a file.
    fn fingerprint((tensors, metadata): &TensorFile) -> u64 {
        let mut h = 0xcbf2_9ce4_8422_2325u64;
        let mut eat = |bytes: &[u8]| {
            for &b in bytes {
                h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
            }
        };
        for (name, t) in tensors {
            eat(name.as_bytes());
            eat(format!("{:?}", t.dtype).as_bytes());
            for &d in &t.shape {
                eat(&(d as u64).to_le_bytes());
            }
            for v in &t.data {
                eat(&v.to_bits().to_le_bytes());
            }
        }
        for (k, v) in metadata {
            eat(k.as_bytes());
            eat(v.as_bytes());
        }
        h
    }

    #[test]
    fn shipped_weights_load_to_the_values_the_hand_written_reader_gave() {
        // fingerprints, value counts and first weights that the hand-written reader (before the
        // `safetensors` crate, commit 05011b4) produced for the three files shipped then (kept as
        // a fixture since the networks were retrained, issue 20)
        let want = [
            ("n.safetensors", 0x21d6_a58c_4c77_f157u64, 1871usize, 0.18808584404447287f64),
            ("n_r.safetensors", 0xcea9_9512_46a1_6e25, 993, 0.1016892501570603),
            ("n_s.safetensors", 0x75c4_b32c_4c81_4b60, 993, 0.10465243938423811),
        ];
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/weights-2026-12-01");
        for (file, hash, count, first) in want {
            let path = dir.join(file);
            let bytes = std::fs::read(&path).expect("shipped weights");
            let parsed = read_bytes(&bytes, file).expect("shipped weights are valid");
            let n: usize = parsed.0.values().map(|t| t.data.len()).sum();
            let w0 = parsed.0["layers.0.weight"].data[0];
            assert!(parsed.0.values().all(|t| t.dtype == Dtype::F64));
            assert_eq!((fingerprint(&parsed), n, w0.to_bits()), (hash, count, first.to_bits()), "{file}");
            // written again: the same length and data bytes (the header's entries may come in
            // another order), and the same tensors and metadata on reading
            let again = write_bytes(&parsed.0, &parsed.1).expect("valid");
            let header_len = |b: &[u8]| 8 + u64::from_le_bytes(b[..8].try_into().expect("8 bytes")) as usize;
            assert_eq!(again.len(), bytes.len());
            assert_eq!(again[header_len(&again)..], bytes[header_len(&bytes)..]);
            assert_eq!(fingerprint(&read_bytes(&again, file).expect("valid")), hash);
            Mlp::load(&path).expect("shipped weights load as networks");
        }
    }

    #[test]
    fn crafted_headers_are_errors_not_panics() {
        // header JSON + `data` bytes
        let file = |h: &str, data: usize| {
            let mut b = with_header(&[0; 8], h);
            b.resize(b.len() + data, 0);
            b
        };
        let big = 1usize << 60;
        // sixteen U8 tensors of ~2^60 bytes each: the declared data ends at 2^64 − 8 bytes
        let mut h = String::from("{");
        for k in 0..16 {
            let len = if k == 15 { big - 8 } else { big };
            h += &format!(r#""t{k}":{{"dtype":"U8","shape":[{len}],"data_offsets":[{},{}]}},"#, k * big, k * big + len);
        }
        h.pop();
        h.push('}');
        for (header, data, want) in [
            (h.as_str(), 8, "outside the 8 data bytes"),
            (r#"{"a":{"dtype":"F64","shape":[4294967296,4294967296],"data_offsets":[0,8]}}"#, 8, "overflows"),
            (r#"{"a":{"dtype":"F64","shape":[1],"data_offsets":[8,0]}}"#, 8, "tile the data"),
            (r#"{"a":{"dtype":"F64","shape":[1],"data_offsets":[0]}}"#, 8, "not valid JSON"),
            (r#"{"a":{"dtype":"F99","shape":[1],"data_offsets":[0,8]}}"#, 8, "not valid JSON"),
            (r#"{"a":{"dtype":"F64","shape":[-1],"data_offsets":[0,8]}}"#, 8, "not valid JSON"),
            (r#"{"a":{"dtype":"F64","shape":[1],"data_offsets":[0,8]},"__metadata__":{"k":1}}"#, 8, "not valid JSON"),
            (r#"{"a":[]}"#, 8, "not valid JSON"),
            (r#"{"a":{"dtype":"U8","shape":[8],"data_offsets":[0,8]}}"#, 8, "`a`: dtype `U8` is not supported"),
            (r#"{"a":{"dtype":"F4","shape":[3],"data_offsets":[0,1]}}"#, 8, "safetensors"),
        ] {
            let m = read_bytes(&file(header, data), "t").expect_err(header).to_string();
            assert!(m.contains(want), "{header}: {m}");
        }
        // an empty file of tensors is valid (and has no network in it)
        let (t, m) = read_bytes(&file("{}", 0), "t").expect("valid");
        assert!(t.is_empty() && m.is_empty());
    }

    #[test]
    fn round_trip_through_a_file_is_exact() {
        let dir = tempfile::tempdir().expect("temp dir");
        let p = dir.path().join("n_r.safetensors");
        let a = net();
        a.save(&p, &[("outputs", "t_r")]).expect("writable");
        let (b, meta) = Mlp::load(&p).expect("valid file");
        assert_eq!(a, b);
        assert_eq!(meta.get("sizes").map(String::as_str), Some("5,20,20,20,1"));
        assert_eq!(meta.get("outputs").map(String::as_str), Some("t_r"));
        // layout on disk: length prefix, header multiple of 8, data size = 8 bytes per value
        let raw = std::fs::read(&p).expect("readable");
        let n = u64::from_le_bytes(raw[..8].try_into().expect("8 bytes")) as usize;
        assert_eq!(n % 8, 0);
        assert_eq!(raw.len() - 8 - n, 8 * (a.n_parameters() + 2 * 5 + 2));
    }

    #[test]
    fn a_mirror_averaged_network_keeps_its_mirror_through_a_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let p = dir.path().join("n_r.safetensors");
        let a = net().with_mirror(Some(super::super::mlp::Mirror::platelet_shape())).expect("fits");
        a.save(&p, &[("outputs", "t_r")]).expect("writable");
        let (b, meta) = Mlp::load(&p).expect("valid file");
        assert_eq!(a, b);
        assert!(meta.get("mirror").is_some_and(|m| m.contains("swap")), "{meta:?}");
        // plain networks have no mirror entry; callers may not set one
        let (_, m) = net().to_tensors(&[]).expect("valid");
        assert!(!m.contains_key("mirror"));
        let e = net().to_tensors(&[("mirror", "x")]).expect_err("reserved");
        assert!(e.to_string().contains("mirror"), "{e}");
        // a bad mirror entry names itself
        let (t, mut m) = a.to_tensors(&[]).expect("valid");
        m.insert("mirror".into(), r#"{"swap":[[3,7]],"reflect":[],"negate":[]}"#.into());
        let e = load(&write_bytes(&t, &m).expect("valid")).expect_err("input 7 of 5");
        assert!(e.to_string().contains("mirror"), "{e}");
        m.insert("mirror".into(), "not json".into());
        let e = load(&write_bytes(&t, &m).expect("valid")).expect_err("not json");
        assert!(e.to_string().contains("metadata mirror"), "{e}");
    }

    #[test]
    fn f32_files_load() {
        let (mut t, m) = net().to_tensors(&[]).expect("valid");
        t.values_mut().for_each(|t| t.dtype = Dtype::F32);
        let b = load(&write_bytes(&t, &m).expect("valid")).expect("F32 loads");
        let a = net();
        for l in 0..a.n_layers() {
            for (x, y) in a.weights(l).iter().zip(b.weights(l)) {
                assert_eq!(*y, *x as f32 as f64);
            }
        }
    }

    #[test]
    fn corrupted_files_give_clear_errors() {
        let good = bytes();
        let msg = |b: &[u8]| load(b).expect_err("corrupted").to_string();
        assert!(msg(&good[..5]).contains("shorter than"));
        let mut big = good.clone();
        big[..8].copy_from_slice(&(1u64 << 40).to_le_bytes());
        assert!(msg(&big).contains("header length"));
        assert!(msg(&good[..good.len() - 8]).contains("outside the"), "{}", msg(&good[..good.len() - 8]));
        let mut trailing = good.clone();
        trailing.extend_from_slice(&[0; 8]);
        assert!(msg(&trailing).contains("trailing"));
        let h = header(&good);
        assert!(msg(&with_header(&good, "{not json")).contains("not valid JSON"));
        assert!(msg(&with_header(&good, &h.replacen("\"F64\"", "\"BF16\"", 1))).contains("allowed F32, F64"));
        assert!(msg(&with_header(&good, &h.replace("\"F64\"", "\"F32\""))).contains("needs"));
        let m = msg(&with_header(&good, &h.replace("5,20,20,20,1", "5,20,21,20,1")));
        assert!(m.contains("layers.1.weight") && m.contains("expected [21, 20]"), "{m}");
        let m = msg(&with_header(&good, &h.replace("\"input.std\"", "\"input.sd\"")));
        assert!(m.contains("input.std") && m.contains("missing"), "{m}");
        // a NaN weight, at the offset the header gives for layers.0.weight
        let v: serde_json::Value = serde_json::from_str(&h).expect("json");
        let begin = v["layers.0.weight"]["data_offsets"][0].as_u64().expect("offset") as usize;
        let n = 8 + h.len();
        let mut nan = good.clone();
        nan[n + begin..n + begin + 8].copy_from_slice(&f64::NAN.to_le_bytes());
        let m = msg(&nan);
        assert!(m.contains("layers.0.weight") && m.contains("not finite"), "{m}");
        let mut zero_std = good.clone();
        let begin = v["input.std"]["data_offsets"][0].as_u64().expect("offset") as usize;
        zero_std[n + begin..n + begin + 8].copy_from_slice(&0.0f64.to_le_bytes());
        assert!(msg(&zero_std).contains("input_std"));
        // two tensors on the same bytes
        let off = v["input.std"]["data_offsets"].to_string();
        let mean_off = v["input.mean"]["data_offsets"].to_string();
        let m = msg(&with_header(&good, &h.replacen(&mean_off, &off, 1)));
        assert!(m.contains("without gaps or overlaps"), "{m}");
        // a tensor the architecture does not have
        let (mut t, meta) = net().to_tensors(&[]).expect("valid");
        t.insert("layers.9.weight".into(), Tensor { shape: vec![1], dtype: Dtype::F32, data: vec![0.0] });
        let m = msg(&write_bytes(&t, &meta).expect("valid"));
        assert!(m.contains("unexpected tensors [\"layers.9.weight\"]"), "{m}");
    }
}
