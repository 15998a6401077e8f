//! Minimal NumPy `.npy` (format 1.0/2.0/3.0) reader and writer for the batch tools: little-endian
//! `f4`/`f8`/`i4`/`i8`/`u1` arrays of any rank, C or Fortran order, and complex `c8`/`c16`
//! ([`read_complex`], [`write_c64`]: numpy stores each value as interleaved re, im). Arrays are
//! returned in C (row-major) order whatever the file's order: real as f64, complex as
//! `Complex<f64>`.

use num_complex::Complex;

/// Single-precision complex sample.
pub type C32 = Complex<f32>;
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
    /// Writing failed; the message names the file (see [`crate::write_atomic`]).
    #[error("{0}")]
    Write(std::io::Error),
    #[error("{path}: not a .npy file ({detail})")]
    Format { path: String, detail: String },
    #[error("{path}: dtype {dtype} is not supported (use float32, float64, int32, int64 or uint8, little endian)")]
    Dtype { path: String, dtype: String },
    #[error("{path}: dtype {dtype} is not complex; expected complex64 (<c8) or complex128 (<c16), little endian")]
    NotComplex { path: String, dtype: String },
}

/// A dense complex array in C order.
#[derive(Clone, Debug, PartialEq)]
pub struct ComplexArray {
    pub shape: Vec<usize>,
    pub data: Vec<Complex<f64>>,
}

fn fmt_err(path: &Path, detail: impl Into<String>) -> NpyError {
    NpyError::Format { path: path.display().to_string(), detail: detail.into() }
}

fn dict_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let k = format!("'{key}':");
    let start = header.find(&k)? + k.len();
    Some(header[start..].trim_start())
}

/// A parsed header: dtype string, Fortran order, shape, and the data bytes.
struct Raw<'a> {
    descr: &'a str,
    fortran: bool,
    shape: Vec<usize>,
    body: &'a [u8],
}

fn parse<'a>(path: &Path, bytes: &'a [u8]) -> Result<Raw<'a>, NpyError> {
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
    Ok(Raw { descr, fortran, shape, body: &bytes[hstart + hlen..] })
}

/// Converts the little-endian bytes of one element.
type Conv<T> = fn(&[u8]) -> T;

fn read_bytes(path: &Path) -> Result<Vec<u8>, NpyError> {
    std::fs::read(path).map_err(|e| NpyError::Io { path: path.display().to_string(), source: e })
}

fn elements<T: Copy + Default>(path: &Path, raw: &Raw<'_>, size: usize, conv: Conv<T>) -> Result<Vec<T>, NpyError> {
    let nbytes = raw
        .shape
        .iter()
        .try_fold(size, |a, &d| a.checked_mul(d))
        .ok_or_else(|| fmt_err(path, format!("shape {:?} is too large", raw.shape)))?;
    if raw.body.len() < nbytes {
        return Err(fmt_err(path, format!("{} data bytes, shape {:?} needs {}", raw.body.len(), raw.shape, nbytes)));
    }
    let flat: Vec<T> = raw.body[..nbytes].chunks_exact(size).map(conv).collect();
    Ok(if raw.fortran && raw.shape.len() > 1 { f_to_c(&flat, &raw.shape) } else { flat })
}

fn f32_at(b: &[u8]) -> f32 {
    f32::from_le_bytes([b[0], b[1], b[2], b[3]])
}

fn f64_at(b: &[u8]) -> f64 {
    f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]])
}

/// Reads a real `.npy` file.
pub fn read(path: &Path) -> Result<Array, NpyError> {
    let bytes = read_bytes(path)?;
    let raw = parse(path, &bytes)?;
    let (size, conv): (usize, Conv<f64>) = match raw.descr {
        "<f4" => (4, |b| f64::from(f32_at(b))),
        "<f8" => (8, f64_at),
        "<i4" => (4, |b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64),
        "<i8" => (8, |b| i64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]) as f64),
        "|u1" | "<u1" => (1, |b| b[0] as f64),
        d => return Err(NpyError::Dtype { path: path.display().to_string(), dtype: d.to_string() }),
    };
    let data = elements(path, &raw, size, conv)?;
    Ok(Array { shape: raw.shape, data })
}

/// Reads a complex `.npy` file: complex64 (`<c8`, interleaved f32 re, im) or complex128
/// (`<c16`, interleaved f64). complex64 values convert to `Complex<f64>` exactly.
pub fn read_complex(path: &Path) -> Result<ComplexArray, NpyError> {
    let bytes = read_bytes(path)?;
    let raw = parse(path, &bytes)?;
    let (size, conv): (usize, Conv<Complex<f64>>) = match raw.descr {
        "<c8" => (8, |b| Complex::new(f64::from(f32_at(&b[..4])), f64::from(f32_at(&b[4..])))),
        "<c16" => (16, |b| Complex::new(f64_at(&b[..8]), f64_at(&b[8..]))),
        d @ ("<f4" | "<f8" | "<i4" | "<i8" | "|u1" | "<u1") => {
            return Err(NpyError::NotComplex { path: path.display().to_string(), dtype: d.to_string() })
        }
        d => return Err(NpyError::Dtype { path: path.display().to_string(), dtype: d.to_string() }),
    };
    let data = elements(path, &raw, size, conv)?;
    Ok(ComplexArray { shape: raw.shape, data })
}

fn f_to_c<T: Copy + Default>(flat: &[T], shape: &[usize]) -> Vec<T> {
    let n = flat.len();
    let mut out = vec![T::default(); n];
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
    crate::write_atomic(path, &out).map_err(NpyError::Write)
}

/// Writes f64 data (C order) atomically.
pub fn write_f64(path: &Path, shape: &[usize], data: &[f64]) -> Result<(), NpyError> {
    let mut out = header("<f8", false, shape);
    out.reserve(data.len() * 8);
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    crate::write_atomic(path, &out).map_err(NpyError::Write)
}

/// Writes complex64 (`<c8`, interleaved little-endian f32 re, im) data in C order atomically.
pub fn write_c64(path: &Path, shape: &[usize], data: &[C32]) -> Result<(), NpyError> {
    let mut out = header("<c8", false, shape);
    out.reserve(data.len() * 8);
    for v in data {
        out.extend_from_slice(&v.re.to_le_bytes());
        out.extend_from_slice(&v.im.to_le_bytes());
    }
    crate::write_atomic(path, &out).map_err(NpyError::Write)
}

/// Writes uint8 (`|u1`) data in C order atomically.
pub fn write_u8(path: &Path, shape: &[usize], data: &[u8]) -> Result<(), NpyError> {
    let mut out = header("|u1", false, shape);
    out.extend_from_slice(data);
    crate::write_atomic(path, &out).map_err(NpyError::Write)
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

    #[test]
    fn complex_round_trip_and_numpy_layout() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.npy");
        let data: Vec<C32> = (0..6).map(|i| C32::new(i as f32 + 0.25, -(i as f32) * 1.5)).collect();
        write_c64(&p, &[2, 3], &data).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let hl = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        assert_eq!((10 + hl) % 64, 0);
        let head = std::str::from_utf8(&bytes[10..10 + hl]).unwrap();
        assert!(head.contains("'descr': '<c8'") && head.contains("'shape': (2, 3)"), "{head}");
        // numpy complex64: interleaved little-endian f32 (re, im).
        let body = &bytes[10 + hl..];
        assert_eq!(body.len(), 48);
        assert_eq!(f32::from_le_bytes([body[8], body[9], body[10], body[11]]), 1.25);
        assert_eq!(f32::from_le_bytes([body[12], body[13], body[14], body[15]]), -1.5);
        let a = read_complex(&p).unwrap();
        assert_eq!(a.shape, vec![2, 3]);
        let back: Vec<C32> = a.data.iter().map(|c| C32::new(c.re as f32, c.im as f32)).collect();
        assert_eq!(back, data);

        // complex128, Fortran order (2, 3): column-major bytes.
        let mut f = header("<c16", true, &[2, 3]);
        for v in [(0.0f64, 1.0f64), (3.0, 4.0), (1.0, 2.0), (4.0, 5.0), (2.0, 3.0), (5.0, 6.0)] {
            f.extend_from_slice(&v.0.to_le_bytes());
            f.extend_from_slice(&v.1.to_le_bytes());
        }
        std::fs::write(&p, &f).unwrap();
        let a = read_complex(&p).unwrap();
        let re: Vec<f64> = a.data.iter().map(|c| c.re).collect();
        let im: Vec<f64> = a.data.iter().map(|c| c.im).collect();
        assert_eq!(re, vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
        assert_eq!(im, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);

        // Real files are refused by read_complex with a named dtype, and vice versa.
        write_f32(&p, &[2], false, &[1.0, 2.0]).unwrap();
        assert!(matches!(read_complex(&p), Err(NpyError::NotComplex { .. })));
        assert!(read_complex(&p).unwrap_err().to_string().contains("<f4 is not complex"));
        let mut t = header("<c8", false, &[3]);
        t.extend_from_slice(&[0u8; 16]);
        std::fs::write(&p, &t).unwrap();
        assert!(read_complex(&p).unwrap_err().to_string().contains("needs 24"));
        let mut b = header(">c8", false, &[1]);
        b.extend_from_slice(&[0u8; 8]);
        std::fs::write(&p, &b).unwrap();
        assert!(read_complex(&p).unwrap_err().to_string().contains("dtype >c8"));

        let u = dir.path().join("u.npy");
        write_u8(&u, &[2, 2], &[0, 1, 2, 3]).unwrap();
        assert_eq!(read(&u).unwrap().data, vec![0.0, 1.0, 2.0, 3.0]);
    }
}
