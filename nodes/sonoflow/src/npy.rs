//! Minimal NumPy `.npy` (format 1.0/2.0/3.0) reader and writer for the batch tools: little-endian
//! `f4`/`f8`/`i4`/`i8`/`u1` arrays of any rank, C or Fortran order. Arrays are returned as f64 in
//! C (row-major) order whatever the file's order.

use std::path::Path;

/// A dense array in C order.
#[derive(Clone, Debug, PartialEq)]
pub struct Array {
    pub shape: Vec<usize>,
    pub data: Vec<f64>,
}

/// Errors reading or writing `.npy` files.
#[derive(Debug, thiserror::Error)]
pub enum NpyError {
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("{path}: not a .npy file ({detail})")]
    Format { path: String, detail: String },
    #[error("{path}: dtype {dtype} is not supported (use float32, float64, int32, int64 or uint8, little endian)")]
    Dtype { path: String, dtype: String },
}

fn fmt_err(path: &Path, detail: impl Into<String>) -> NpyError {
    NpyError::Format { path: path.display().to_string(), detail: detail.into() }
}

fn dict_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let k = format!("'{key}':");
    let start = header.find(&k)? + k.len();
    Some(header[start..].trim_start())
}

/// Reads a `.npy` file.
pub fn read(path: &Path) -> Result<Array, NpyError> {
    let bytes = std::fs::read(path).map_err(|e| NpyError::Io { path: path.display().to_string(), source: e })?;
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(fmt_err(path, "missing the \\x93NUMPY magic"));
    }
    let (hlen, hstart) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12),
        v => return Err(fmt_err(path, format!("unsupported format version {v}"))),
    };
    let header = bytes
        .get(hstart..hstart + hlen)
        .and_then(|h| std::str::from_utf8(h).ok())
        .ok_or_else(|| fmt_err(path, "truncated header"))?;
    let descr = dict_value(header, "descr")
        .and_then(|v| v.strip_prefix('\''))
        .and_then(|v| v.split('\'').next())
        .ok_or_else(|| fmt_err(path, "no descr"))?;
    let fortran = dict_value(header, "fortran_order").map(|v| v.starts_with("True")).unwrap_or(false);
    let shape_txt = dict_value(header, "shape")
        .and_then(|v| v.strip_prefix('('))
        .and_then(|v| v.split(')').next())
        .ok_or_else(|| fmt_err(path, "no shape"))?;
    let shape: Vec<usize> = shape_txt
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>().map_err(|_| fmt_err(path, format!("bad shape ({shape_txt})"))))
        .collect::<Result<_, _>>()?;
    let n: usize = shape.iter().product();
    let body = &bytes[hstart + hlen..];
    let (size, conv): (usize, fn(&[u8]) -> f64) = match descr {
        "<f4" => (4, |b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64),
        "<f8" => (8, |b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]])),
        "<i4" => (4, |b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64),
        "<i8" => (8, |b| i64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]) as f64),
        "|u1" | "<u1" => (1, |b| b[0] as f64),
        d => return Err(NpyError::Dtype { path: path.display().to_string(), dtype: d.to_string() }),
    };
    if body.len() < n * size {
        return Err(fmt_err(path, format!("{} data bytes, shape {shape:?} needs {}", body.len(), n * size)));
    }
    let flat: Vec<f64> = body[..n * size].chunks_exact(size).map(conv).collect();
    let data = if fortran && shape.len() > 1 { f_to_c(&flat, &shape) } else { flat };
    Ok(Array { shape, data })
}

fn f_to_c(flat: &[f64], shape: &[usize]) -> Vec<f64> {
    let n = flat.len();
    let mut out = vec![0.0; n];
    let rank = shape.len();
    let mut idx = vec![0usize; rank];
    for v in flat {
        // Fortran order: first index fastest.
        let mut c = 0;
        for d in 0..rank {
            c = c * shape[d] + idx[d];
        }
        out[c] = *v;
        for d in 0..rank {
            idx[d] += 1;
            if idx[d] < shape[d] {
                break;
            }
            idx[d] = 0;
        }
    }
    out
}

fn header(descr: &str, fortran: bool, shape: &[usize]) -> Vec<u8> {
    let shape_txt = match shape.len() {
        1 => format!("({},)", shape[0]),
        _ => format!("({})", shape.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", ")),
    };
    let mut h = format!(
        "{{'descr': '{descr}', 'fortran_order': {}, 'shape': {shape_txt}, }}",
        if fortran { "True" } else { "False" }
    );
    // Pad so that the data starts on a multiple of 64 bytes, header ends with '\n'.
    let total = 10 + h.len() + 1;
    h.push_str(&" ".repeat((64 - total % 64) % 64));
    h.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(h.len() as u16).to_le_bytes());
    out.extend_from_slice(h.as_bytes());
    out
}

/// Writes f32 data atomically. `fortran = true` declares column-major data (the last index is
/// slowest), which lets an element-major RF buffer be saved as shape (n_samples, n_elements)
/// without a transpose.
pub fn write_f32(path: &Path, shape: &[usize], fortran: bool, data: &[f32]) -> Result<(), NpyError> {
    let mut out = header("<f4", fortran, shape);
    out.reserve(data.len() * 4);
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    crate::nodeutil::write_atomic(path, &out).map_err(|e| NpyError::Io { path: path.display().to_string(), source: e })
}

/// Writes f64 data (C order) atomically.
pub fn write_f64(path: &Path, shape: &[usize], data: &[f64]) -> Result<(), NpyError> {
    let mut out = header("<f8", false, shape);
    out.reserve(data.len() * 8);
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    crate::nodeutil::write_atomic(path, &out).map_err(|e| NpyError::Io { path: path.display().to_string(), source: e })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_c_and_fortran() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.npy");
        // Element-major buffer of 3 elements × 4 samples, saved as (4 samples, 3 elements).
        let data: Vec<f32> = (0..12).map(|i| i as f32).collect();
        write_f32(&p, &[4, 3], true, &data).unwrap();
        let a = read(&p).unwrap();
        assert_eq!(a.shape, vec![4, 3]);
        // C order (sample k, element e) = data[e * 4 + k].
        for k in 0..4 {
            for e in 0..3 {
                assert_eq!(a.data[k * 3 + e], data[e * 4 + k] as f64);
            }
        }
        let bytes = std::fs::read(&p).unwrap();
        let hl = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        assert_eq!((10 + hl) % 64, 0);
        let p2 = dir.path().join("b.npy");
        write_f64(&p2, &[5], &[1.0, -2.5, 3.0, 1e-300, f64::MAX]).unwrap();
        assert_eq!(read(&p2).unwrap().data, vec![1.0, -2.5, 3.0, 1e-300, f64::MAX]);
    }

    #[test]
    fn bad_files_name_the_problem() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.npy");
        std::fs::write(&p, b"hello world, not numpy").unwrap();
        assert!(read(&p).unwrap_err().to_string().contains("magic"));
        let mut h = header("<c8", false, &[2]);
        h.extend_from_slice(&[0u8; 16]);
        std::fs::write(&p, &h).unwrap();
        assert!(read(&p).unwrap_err().to_string().contains("dtype <c8"));
        let mut h = header("<f4", false, &[4]);
        h.extend_from_slice(&[0u8; 8]);
        std::fs::write(&p, &h).unwrap();
        assert!(read(&p).unwrap_err().to_string().contains("needs 16"));
        assert!(matches!(read(&dir.path().join("missing.npy")), Err(NpyError::Io { .. })));
    }
}
