//! Network weights in the safetensors format (<https://github.com/huggingface/safetensors>),
//! hand-written (the format is three lines of specification; no extra dependency):
//!
//! - 8 bytes: N, the header length, u64 little-endian;
//! - N bytes: a UTF-8 JSON object `{name: {"dtype": "F32"|"F64", "shape": [...], "data_offsets":
//!   [begin, end]}, …, "__metadata__": {string: string}}`, padded with spaces to a multiple of 8;
//! - the data: each tensor's values little-endian, row-major, at `begin..end` of the bytes after
//!   the header; the tensors tile that buffer with no gap and no overlap.
//!
//! [`read_bytes`] checks all of that and never panics on a bad file. An [`Mlp`] is stored as
//! `layers.{l}.weight` (shape \[n_{l+1}, n_l\], PyTorch's `Linear` layout), `layers.{l}.bias`,
//! `input.mean`, `input.std`, `output.mean`, `output.scale` (F64, so a round trip is exact; F32
//! files, e.g. from PyTorch, load too) and the metadata `format` = `sonoflow-mlp`, `version` =
//! `1`, `sizes` (e.g. `6,50,20,20,3`), `activation` = `relu`, for a mirror-averaged network
//! `mirror` (the [`super::mlp::Mirror`] as JSON, e.g. `{"swap":[[3,4]],"reflect":[[5,6.283185307179586]],"negate":[2]}`),
//! plus any caller entries.

use super::mlp::Mlp;
use super::NnError;
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

impl Dtype {
    fn name(self) -> &'static str {
        match self {
            Dtype::F32 => "F32",
            Dtype::F64 => "F64",
        }
    }
    fn size(self) -> usize {
        match self {
            Dtype::F32 => 4,
            Dtype::F64 => 8,
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

/// Largest header accepted (the format's reference implementation uses 100 MB).
const MAX_HEADER: u64 = 100_000_000;

/// The safetensors bytes of `tensors` and `metadata` (tensors stored in name order).
pub fn write_bytes(
    tensors: &BTreeMap<String, Tensor>,
    metadata: &BTreeMap<String, String>,
) -> Result<Vec<u8>, NnError> {
    let mut header = serde_json::Map::new();
    let mut offset = 0usize;
    for (name, t) in tensors {
        let numel: usize = t.shape.iter().product();
        if numel != t.data.len() || name == "__metadata__" {
            return Err(NnError::Tensor {
                path: "<memory>".into(),
                tensor: name.clone(),
                reason: format!(
                    "shape {:?} holds {numel} values, data has {} (or a reserved name)",
                    t.shape,
                    t.data.len()
                ),
            });
        }
        let end = offset + numel * t.dtype.size();
        header.insert(
            name.clone(),
            serde_json::json!({ "dtype": t.dtype.name(), "shape": t.shape, "data_offsets": [offset, end] }),
        );
        offset = end;
    }
    if !metadata.is_empty() {
        header.insert("__metadata__".into(), serde_json::json!(metadata));
    }
    let mut json = serde_json::Value::Object(header).to_string().into_bytes();
    let padding = (8 - json.len() % 8) % 8;
    json.resize(json.len() + padding, b' ');
    let mut out = Vec::with_capacity(8 + json.len() + offset);
    out.extend_from_slice(&(json.len() as u64).to_le_bytes());
    out.extend_from_slice(&json);
    for t in tensors.values() {
        for &v in &t.data {
            match t.dtype {
                Dtype::F32 => out.extend_from_slice(&(v as f32).to_le_bytes()),
                Dtype::F64 => out.extend_from_slice(&v.to_le_bytes()),
            }
        }
    }
    Ok(out)
}

/// Parses and validates safetensors `bytes` (`path` names the file in errors).
pub fn read_bytes(bytes: &[u8], path: &str) -> Result<TensorFile, NnError> {
    let format = |reason: String| NnError::Format { path: path.into(), reason };
    let tensor_err =
        |tensor: &str, reason: String| NnError::Tensor { path: path.into(), tensor: tensor.into(), reason };
    let len_bytes: [u8; 8] = bytes
        .get(..8)
        .and_then(|b| b.try_into().ok())
        .ok_or_else(|| format(format!("{} bytes: shorter than the 8-byte header length", bytes.len())))?;
    let n = u64::from_le_bytes(len_bytes);
    if n > MAX_HEADER || n > (bytes.len() - 8) as u64 {
        return Err(format(format!(
            "header length {n} exceeds the file ({} bytes after the length) or {MAX_HEADER}",
            bytes.len() - 8
        )));
    }
    let n = n as usize;
    let header = std::str::from_utf8(&bytes[8..8 + n]).map_err(|e| format(format!("header is not UTF-8: {e}")))?;
    let header: serde_json::Value =
        serde_json::from_str(header).map_err(|e| format(format!("header is not valid JSON: {e}")))?;
    let header = header.as_object().ok_or_else(|| format("header is not a JSON object".into()))?;
    let buffer = &bytes[8 + n..];
    let mut metadata = BTreeMap::new();
    let mut tensors = BTreeMap::new();
    let mut ranges = Vec::new();
    for (name, entry) in header {
        if name == "__metadata__" {
            let m = entry.as_object().ok_or_else(|| format("`__metadata__` is not an object".into()))?;
            for (k, v) in m {
                let v = v.as_str().ok_or_else(|| format(format!("metadata `{k}` is not a string")))?;
                metadata.insert(k.clone(), v.to_string());
            }
            continue;
        }
        let e = entry.as_object().ok_or_else(|| tensor_err(name, "entry is not an object".into()))?;
        let dtype = match e.get("dtype").and_then(|d| d.as_str()) {
            Some("F32") => Dtype::F32,
            Some("F64") => Dtype::F64,
            Some(other) => return Err(tensor_err(name, format!("dtype `{other}` is not supported: allowed F32, F64"))),
            None => return Err(tensor_err(name, "no string `dtype`".into())),
        };
        let ints = |key: &str| -> Result<Vec<usize>, NnError> {
            e.get(key)
                .and_then(|s| s.as_array())
                .ok_or_else(|| tensor_err(name, format!("no array `{key}`")))?
                .iter()
                .map(|v| {
                    v.as_u64()
                        .and_then(|x| usize::try_from(x).ok())
                        .ok_or_else(|| tensor_err(name, format!("`{key}` holds {v}, not a non-negative integer")))
                })
                .collect()
        };
        let shape = ints("shape")?;
        let offsets = ints("data_offsets")?;
        let [begin, end] = offsets[..] else {
            return Err(tensor_err(name, format!("`data_offsets` has {} entries, expected 2", offsets.len())));
        };
        if begin > end || end > buffer.len() {
            return Err(tensor_err(
                name,
                format!("data_offsets [{begin}, {end}] outside the {} data bytes", buffer.len()),
            ));
        }
        let numel = shape
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d))
            .ok_or_else(|| tensor_err(name, format!("shape {shape:?} overflows")))?;
        if numel.checked_mul(dtype.size()) != Some(end - begin) {
            return Err(tensor_err(
                name,
                format!(
                    "shape {shape:?} of {} needs {numel} × {} bytes, data_offsets give {}",
                    dtype.name(),
                    dtype.size(),
                    end - begin
                ),
            ));
        }
        let raw = &buffer[begin..end];
        let data: Vec<f64> = match dtype {
            Dtype::F32 => raw.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64).collect(),
            Dtype::F64 => raw
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
                .collect(),
        };
        ranges.push((begin, end, name.clone()));
        tensors.insert(name.clone(), Tensor { shape, dtype, data });
    }
    ranges.sort();
    let mut at = 0;
    for (begin, end, name) in &ranges {
        if *begin != at {
            return Err(tensor_err(
                name,
                format!("data starts at byte {begin}, expected {at}: the tensors must tile the data without gaps or overlaps"),
            ));
        }
        at = *end;
    }
    if at != buffer.len() {
        return Err(format(format!("{} trailing data bytes after the last tensor", buffer.len() - at)));
    }
    Ok((tensors, metadata))
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
        // `safetensors` crate, commit 05011b4) produced for the three shipped files
        let want = [
            ("n.safetensors", 0x21d6_a58c_4c77_f157u64, 1871usize, 0.18808584404447287f64),
            ("n_r.safetensors", 0xcea9_9512_46a1_6e25, 993, 0.1016892501570603),
            ("n_s.safetensors", 0x75c4_b32c_4c81_4b60, 993, 0.10465243938423811),
        ];
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("weights");
        for (file, hash, count, first) in want {
            let path = dir.join(file);
            let bytes = std::fs::read(&path).expect("shipped weights");
            let parsed = read_bytes(&bytes, file).expect("shipped weights are valid");
            let n: usize = parsed.0.values().map(|t| t.data.len()).sum();
            let w0 = parsed.0["layers.0.weight"].data[0];
            assert!(parsed.0.values().all(|t| t.dtype == Dtype::F64));
            assert_eq!((fingerprint(&parsed), n, w0.to_bits()), (hash, count, first.to_bits()), "{file}");
            Mlp::load(&path).expect("shipped weights load as networks");
        }
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
