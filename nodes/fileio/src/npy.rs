//! NumPy `.npy` arrays for the batch tools, read and written through the maintained [`npyz`]
//! crate (format versions 1.0, 2.0 and 3.0).
//!
//! * Reading: real `f4`/`f8`/`i4`/`i8`/`u1` arrays ([`read`], returned as f64) and complex
//!   `c8`/`c16` arrays ([`read_complex`], returned as `Complex<f64>`), of any rank, in C or
//!   Fortran order, little or big endian. Arrays are returned in C (row-major) order whatever the
//!   file's order. Any other dtype is refused with an error that names the file, the dtype found
//!   and the dtypes accepted; truncated or malformed files give an error, never a panic.
//! * Writing: little-endian float32, float64, complex64 (numpy's interleaved re, im) and uint8
//!   ([`write_f32`], [`write_f64`], [`write_c64`], [`write_u8`]), encoded in memory and then
//!   written with [`crate::write_atomic`], so no reader ever sees half a file.

use std::io;
use std::path::Path;

use npyz::{DType, NpyFile, NpyHeader, Order, TypeChar, TypeStr, WriteOptions, WriterBuilder};
use num_complex::Complex;

/// Single-precision complex sample.
pub type C32 = Complex<f32>;

/// A dense array in C order.
#[derive(Clone, Debug, PartialEq)]
pub struct Array {
    pub shape: Vec<usize>,
    pub data: Vec<f64>,
}

/// A dense complex array in C order.
#[derive(Clone, Debug, PartialEq)]
pub struct ComplexArray {
    pub shape: Vec<usize>,
    pub data: Vec<Complex<f64>>,
}

/// The dtypes [`read`] accepts.
const REAL_DTYPES: &str = "float32 (f4), float64 (f8), int32 (i4), int64 (i8) or uint8 (u1)";
/// The dtypes [`read_complex`] accepts.
const COMPLEX_DTYPES: &str = "complex64 (c8) or complex128 (c16)";

/// Errors reading or writing `.npy` files.
#[derive(Debug, thiserror::Error)]
pub enum NpyError {
    #[error("{path}: {source}")]
    Io { path: String, source: io::Error },
    #[error("{path}: not a .npy file ({detail})")]
    Format { path: String, detail: String },
    #[error("{path}: dtype {dtype} is not supported; expected {expected}")]
    Dtype { path: String, dtype: String, expected: &'static str },
    #[error("{path}: dtype {dtype} is not complex; expected complex64 (c8) or complex128 (c16)")]
    NotComplex { path: String, dtype: String },
    #[error("{path}: shape {shape:?} holds {expected} values, but {got} were given")]
    Shape { path: String, shape: Vec<usize>, expected: usize, got: usize },
}

fn fmt_err(path: &Path, detail: impl Into<String>) -> NpyError {
    NpyError::Format { path: path.display().to_string(), detail: detail.into() }
}

fn io_err(path: &Path, source: io::Error) -> NpyError {
    NpyError::Io { path: path.display().to_string(), source }
}

/// The dtype as numpy spells it (`<f4`, `>c8`, or a structured dtype's description).
fn dtype_name(dtype: &DType) -> String {
    match dtype {
        DType::Plain(ts) => ts.to_string(),
        other => other.descr(),
    }
}

/// A parsed file: its header, its C-order shape and element count, and its data bytes (at least
/// `len` elements of the header's dtype: checked here, so reading them cannot run short).
struct Parsed<'a> {
    header: NpyHeader,
    shape: Vec<usize>,
    len: usize,
    data: &'a [u8],
}

fn parse<'a>(path: &Path, bytes: &'a [u8]) -> Result<Parsed<'a>, NpyError> {
    let mut cursor = io::Cursor::new(bytes);
    let header = match NpyHeader::from_reader(&mut cursor) {
        Ok(h) => h,
        Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => return Err(fmt_err(path, "truncated header")),
        Err(e) => return Err(fmt_err(path, e.to_string())),
    };
    let offset = cursor.position();
    // npyz 0.8 multiplies the header's dimensions unchecked (its element count and strides): the
    // root Cargo.toml turns its overflow checks off in dev builds too, so a shape whose size
    // overflows wraps there instead of panicking, and the checked product here refuses it.
    let shape = header
        .shape()
        .iter()
        .map(|&d| usize::try_from(d).ok())
        .collect::<Option<Vec<usize>>>()
        .ok_or_else(|| fmt_err(path, format!("shape {:?} is too large", header.shape())))?;
    let len = shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
    let item = header.dtype().num_bytes();
    let nbytes = len
        .zip(item)
        .and_then(|(n, s)| n.checked_mul(s))
        .ok_or_else(|| fmt_err(path, format!("shape {shape:?} is too large")))?;
    let data = usize::try_from(offset).ok().and_then(|o| bytes.get(o..)).unwrap_or_default();
    if data.len() < nbytes {
        return Err(fmt_err(path, format!("{} data bytes, shape {shape:?} needs {nbytes}", data.len())));
    }
    Ok(Parsed { header, len: len.unwrap_or_default(), shape, data })
}

/// Reads all elements as `T` (in file order), then converts them and puts them in C order.
fn elements<T: npyz::Deserialize, U: Copy + Default>(
    path: &Path,
    p: Parsed<'_>,
    conv: fn(T) -> U,
) -> Result<(Vec<usize>, Vec<U>), NpyError> {
    let fortran = p.header.order() == Order::Fortran;
    let reader = NpyFile::with_header(p.header, p.data).data::<T>().map_err(|e| fmt_err(path, e.to_string()))?;
    let mut flat = Vec::with_capacity(p.len);
    for v in reader {
        flat.push(conv(v.map_err(|e| io_err(path, e))?));
    }
    let data = if fortran && p.shape.len() > 1 { f_to_c(&flat, &p.shape) } else { flat };
    Ok((p.shape, data))
}

fn read_bytes(path: &Path) -> Result<Vec<u8>, NpyError> {
    std::fs::read(path).map_err(|e| io_err(path, e))
}

/// The scalar dtype's kind and size in bytes, `None` for a structured or sub-array dtype.
fn scalar(dtype: &DType) -> Option<(TypeChar, u64)> {
    match dtype {
        DType::Plain(ts) => Some((ts.type_char(), ts.size_field())),
        _ => None,
    }
}

/// Reads a real `.npy` file (float32, float64, int32, int64 or uint8) as f64.
pub fn read(path: &Path) -> Result<Array, NpyError> {
    let bytes = read_bytes(path)?;
    let p = parse(path, &bytes)?;
    let dtype = p.header.dtype();
    let (shape, data) = match scalar(&dtype) {
        Some((TypeChar::Float, 4)) => elements::<f32, _>(path, p, f64::from)?,
        Some((TypeChar::Float, 8)) => elements::<f64, _>(path, p, |v| v)?,
        Some((TypeChar::Int, 4)) => elements::<i32, _>(path, p, f64::from)?,
        Some((TypeChar::Int, 8)) => elements::<i64, _>(path, p, |v| v as f64)?,
        Some((TypeChar::Uint, 1)) => elements::<u8, _>(path, p, f64::from)?,
        _ => {
            return Err(NpyError::Dtype {
                path: path.display().to_string(),
                dtype: dtype_name(&dtype),
                expected: REAL_DTYPES,
            })
        }
    };
    Ok(Array { shape, data })
}

/// Reads a complex `.npy` file: complex64 (`c8`, interleaved f32 re, im) or complex128 (`c16`,
/// interleaved f64). complex64 values convert to `Complex<f64>` exactly.
pub fn read_complex(path: &Path) -> Result<ComplexArray, NpyError> {
    let bytes = read_bytes(path)?;
    let p = parse(path, &bytes)?;
    let dtype = p.header.dtype();
    let (shape, data) = match scalar(&dtype) {
        Some((TypeChar::Complex, 8)) => {
            elements::<Complex<f32>, _>(path, p, |c| Complex::new(f64::from(c.re), f64::from(c.im)))?
        }
        Some((TypeChar::Complex, 16)) => elements::<Complex<f64>, _>(path, p, |c| c)?,
        Some((TypeChar::Float, 4 | 8) | (TypeChar::Int, 4 | 8) | (TypeChar::Uint, 1)) => {
            return Err(NpyError::NotComplex { path: path.display().to_string(), dtype: dtype_name(&dtype) })
        }
        _ => {
            return Err(NpyError::Dtype {
                path: path.display().to_string(),
                dtype: dtype_name(&dtype),
                expected: COMPLEX_DTYPES,
            })
        }
    };
    Ok(ComplexArray { shape, data })
}

/// Fortran-order (first index fastest) data to C order (last index fastest).
fn f_to_c<T: Copy + Default>(flat: &[T], shape: &[usize]) -> Vec<T> {
    let n = flat.len();
    let mut out = vec![T::default(); n];
    let rank = shape.len();
    let mut idx = vec![0usize; rank];
    for v in flat {
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

/// Encodes `data` with dtype `descr` (a numpy type string such as `<f4`) and writes it atomically.
fn write<T: npyz::Serialize>(
    path: &Path,
    descr: &str,
    shape: &[usize],
    order: Order,
    data: &[T],
) -> Result<(), NpyError> {
    let expected = shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
    if expected != Some(data.len()) {
        return Err(NpyError::Shape {
            path: path.display().to_string(),
            shape: shape.to_vec(),
            expected: expected.unwrap_or(usize::MAX),
            got: data.len(),
        });
    }
    let ts: TypeStr = descr.parse().map_err(|e| io_err(path, io::Error::other(format!("dtype {descr}: {e}"))))?;
    let shape_u64: Vec<u64> = shape.iter().map(|&d| d as u64).collect();
    let mut out = Vec::with_capacity(128 + std::mem::size_of_val(data));
    let mut w = WriteOptions::<T>::new()
        .dtype(DType::new_scalar(ts))
        .shape(&shape_u64)
        .order(order)
        .writer(&mut out)
        .begin_nd()
        .map_err(|e| io_err(path, e))?;
    for v in data {
        w.push(v).map_err(|e| io_err(path, e))?;
    }
    w.finish().map_err(|e| io_err(path, e))?;
    crate::write_atomic(path, &out).map_err(|e| io_err(path, e))
}

/// Writes f32 data atomically. `fortran = true` declares column-major data (the last index is
/// slowest), which lets an element-major RF buffer be saved as shape (n_samples, n_elements)
/// without a transpose.
pub fn write_f32(path: &Path, shape: &[usize], fortran: bool, data: &[f32]) -> Result<(), NpyError> {
    write(path, "<f4", shape, if fortran { Order::Fortran } else { Order::C }, data)
}

/// Writes f64 data (C order) atomically.
pub fn write_f64(path: &Path, shape: &[usize], data: &[f64]) -> Result<(), NpyError> {
    write(path, "<f8", shape, Order::C, data)
}

/// Writes complex64 (`<c8`, interleaved little-endian f32 re, im) data in C order atomically.
pub fn write_c64(path: &Path, shape: &[usize], data: &[C32]) -> Result<(), NpyError> {
    write(path, "<c8", shape, Order::C, data)
}

/// Writes uint8 (`|u1`) data in C order atomically.
pub fn write_u8(path: &Path, shape: &[usize], data: &[u8]) -> Result<(), NpyError> {
    write(path, "|u1", shape, Order::C, data)
}

#[cfg(test)]
mod tests {
    use super::*;

    // Files written by numpy 2.4.6 itself, each with `f = io.BytesIO(); <line>; f.getvalue()`.
    // The header is padded with spaces to a multiple of 64 bytes; `\x20` keeps the first space of
    // the padding from being eaten by the line continuation.

    /// `np.save(f, np.arange(6, dtype='<f4').reshape(2, 3) * 0.5)`
    const NUMPY_F4_C: &[u8] = b"\x93NUMPY\x01\x00v\x00{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }\
        \x20                                                         \n\
        \x00\x00\x00\x00\x00\x00\x00?\x00\x00\x80?\x00\x00\xc0?\x00\x00\x00@\x00\x00 @";
    /// `np.save(f, np.asfortranarray((np.arange(6, dtype='<f8') - 2).reshape(2, 3)))`
    const NUMPY_F8_FORTRAN: &[u8] = b"\x93NUMPY\x01\x00v\x00{'descr': '<f8', 'fortran_order': True, 'shape': (2, 3), }\
        \x20                                                          \n\
        \x00\x00\x00\x00\x00\x00\x00\xc0\x00\x00\x00\x00\x00\x00\xf0?\x00\x00\x00\x00\x00\x00\xf0\xbf\
        \x00\x00\x00\x00\x00\x00\x00@\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x08@";
    /// `np.save(f, np.array([1 + 2j, -0.5 - 3.25j], dtype='<c8'))`
    const NUMPY_C8: &[u8] = b"\x93NUMPY\x01\x00v\x00{'descr': '<c8', 'fortran_order': False, 'shape': (2,), }\
        \x20                                                           \n\
        \x00\x00\x80?\x00\x00\x00@\x00\x00\x00\xbf\x00\x00P\xc0";
    /// `np.save(f, np.array([1.5, -2.0], dtype='>f8'))`
    const NUMPY_F8_BIG_ENDIAN: &[u8] =
        b"\x93NUMPY\x01\x00v\x00{'descr': '>f8', 'fortran_order': False, 'shape': (2,), }\
        \x20                                                           \n\
        ?\xf8\x00\x00\x00\x00\x00\x00\xc0\x00\x00\x00\x00\x00\x00\x00";
    /// `np.save(f, np.array([[0, 255], [7, 8]], dtype='u1'))`
    const NUMPY_U1: &[u8] = b"\x93NUMPY\x01\x00v\x00{'descr': '|u1', 'fortran_order': False, 'shape': (2, 2), }\
        \x20                                                         \n\
        \x00\xff\x07\x08";

    /// A .npy file with the given header dictionary (version 1.0, padded like numpy) and body.
    fn handmade(dict: &str, body: &[u8]) -> Vec<u8> {
        let mut h = dict.to_string();
        h.push_str(&" ".repeat((64 - (10 + h.len() + 1) % 64) % 64));
        h.push('\n');
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend_from_slice(&(h.len() as u16).to_le_bytes());
        out.extend_from_slice(h.as_bytes());
        out.extend_from_slice(body);
        out
    }

    fn header_text(bytes: &[u8]) -> &str {
        let hl = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        std::str::from_utf8(&bytes[10..10 + hl]).unwrap()
    }

    #[test]
    fn reads_files_written_by_numpy() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("n.npy");
        std::fs::write(&p, NUMPY_F4_C).unwrap();
        assert_eq!(read(&p).unwrap(), Array { shape: vec![2, 3], data: vec![0.0, 0.5, 1.0, 1.5, 2.0, 2.5] });
        // Fortran order comes back in C order: row 0 is (-2, -1, 0), row 1 is (1, 2, 3).
        std::fs::write(&p, NUMPY_F8_FORTRAN).unwrap();
        assert_eq!(read(&p).unwrap(), Array { shape: vec![2, 3], data: vec![-2.0, -1.0, 0.0, 1.0, 2.0, 3.0] });
        std::fs::write(&p, NUMPY_C8).unwrap();
        let c = read_complex(&p).unwrap();
        assert_eq!(c.shape, vec![2]);
        assert_eq!(c.data, vec![Complex::new(1.0, 2.0), Complex::new(-0.5, -3.25)]);
        // Big endian is converted.
        std::fs::write(&p, NUMPY_F8_BIG_ENDIAN).unwrap();
        assert_eq!(read(&p).unwrap(), Array { shape: vec![2], data: vec![1.5, -2.0] });
        std::fs::write(&p, NUMPY_U1).unwrap();
        assert_eq!(read(&p).unwrap(), Array { shape: vec![2, 2], data: vec![0.0, 255.0, 7.0, 8.0] });
    }

    #[test]
    fn written_files_match_numpy_layout() {
        // The data bytes after the header are exactly what numpy writes for the same array.
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("w.npy");
        let body = |b: &[u8]| b[10 + u16::from_le_bytes([b[8], b[9]]) as usize..].to_vec();
        write_f32(&p, &[2, 3], false, &[0.0, 0.5, 1.0, 1.5, 2.0, 2.5]).unwrap();
        let w = std::fs::read(&p).unwrap();
        assert_eq!(body(&w), body(NUMPY_F4_C));
        assert!(header_text(&w).contains("'descr': '<f4', 'fortran_order': False"), "{}", header_text(&w));
        write_c64(&p, &[2], &[C32::new(1.0, 2.0), C32::new(-0.5, -3.25)]).unwrap();
        let w = std::fs::read(&p).unwrap();
        assert_eq!(body(&w), body(NUMPY_C8));
        assert!(header_text(&w).contains("'descr': '<c8'"), "{}", header_text(&w));
        write_u8(&p, &[2, 2], &[0, 255, 7, 8]).unwrap();
        let w = std::fs::read(&p).unwrap();
        assert_eq!(body(&w), body(NUMPY_U1));
        assert!(header_text(&w).contains("'descr': '|u1'"), "{}", header_text(&w));
        // The data start is aligned (npyz pads to 16 bytes; numpy to 64, and reads either).
        assert_eq!((w.len() - 4) % 16, 0);
    }

    #[test]
    fn round_trip_c_and_fortran() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.npy");
        // Element-major buffer of 3 elements × 4 samples, saved as (4 samples, 3 elements).
        let data: Vec<f32> = (0..12).map(|i| i as f32).collect();
        write_f32(&p, &[4, 3], true, &data).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        assert!(header_text(&bytes).contains("'fortran_order': True"));
        let a = read(&p).unwrap();
        assert_eq!(a.shape, vec![4, 3]);
        // C order (sample k, element e) = data[e * 4 + k].
        for k in 0..4 {
            for e in 0..3 {
                assert_eq!(a.data[k * 3 + e], data[e * 4 + k] as f64);
            }
        }
        let p2 = dir.path().join("b.npy");
        write_f64(&p2, &[5], &[1.0, -2.5, 3.0, 1e-300, f64::MAX]).unwrap();
        assert_eq!(read(&p2).unwrap().data, vec![1.0, -2.5, 3.0, 1e-300, f64::MAX]);
        // Rank 3, and an empty array.
        let d3: Vec<f64> = (0..24).map(|i| i as f64 * 0.25 - 3.0).collect();
        write_f64(&p2, &[2, 3, 4], &d3).unwrap();
        assert_eq!(read(&p2).unwrap(), Array { shape: vec![2, 3, 4], data: d3 });
        write_f32(&p2, &[0, 3], false, &[]).unwrap();
        assert_eq!(read(&p2).unwrap(), Array { shape: vec![0, 3], data: vec![] });
        // f32 special values survive.
        write_f32(&p2, &[3], false, &[f32::INFINITY, -0.0, f32::MIN_POSITIVE]).unwrap();
        let v = read(&p2).unwrap().data;
        assert_eq!(v, vec![f64::INFINITY, 0.0, f64::from(f32::MIN_POSITIVE)]);
        assert!(v[1].is_sign_negative());
        write_f32(&p2, &[1], false, &[f32::NAN]).unwrap();
        assert!(read(&p2).unwrap().data[0].is_nan());
        let u = dir.path().join("u.npy");
        write_u8(&u, &[2, 2], &[0, 1, 2, 255]).unwrap();
        assert_eq!(read(&u).unwrap().data, vec![0.0, 1.0, 2.0, 255.0]);
    }

    #[test]
    fn integer_dtypes_read_as_f64() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("i.npy");
        let mut body = Vec::new();
        for v in [-3i32, 0, 7] {
            body.extend_from_slice(&v.to_le_bytes());
        }
        std::fs::write(&p, handmade("{'descr': '<i4', 'fortran_order': False, 'shape': (3,), }", &body)).unwrap();
        assert_eq!(read(&p).unwrap().data, vec![-3.0, 0.0, 7.0]);
        let mut body = Vec::new();
        for v in [-1i64 << 40, 5] {
            body.extend_from_slice(&v.to_le_bytes());
        }
        std::fs::write(&p, handmade("{'descr': '<i8', 'fortran_order': False, 'shape': (2,), }", &body)).unwrap();
        assert_eq!(read(&p).unwrap().data, vec![-(2f64.powi(40)), 5.0]);
    }

    #[test]
    fn complex_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.npy");
        let data: Vec<C32> = (0..6).map(|i| C32::new(i as f32 + 0.25, -(i as f32) * 1.5)).collect();
        write_c64(&p, &[2, 3], &data).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let head = header_text(&bytes);
        assert!(head.contains("'descr': '<c8'") && head.contains("'shape': (2, 3"), "{head}");
        // numpy complex64: interleaved little-endian f32 (re, im).
        let body = &bytes[bytes.len() - 48..];
        assert_eq!(f32::from_le_bytes([body[8], body[9], body[10], body[11]]), 1.25);
        assert_eq!(f32::from_le_bytes([body[12], body[13], body[14], body[15]]), -1.5);
        let a = read_complex(&p).unwrap();
        assert_eq!(a.shape, vec![2, 3]);
        let back: Vec<C32> = a.data.iter().map(|c| C32::new(c.re as f32, c.im as f32)).collect();
        assert_eq!(back, data);

        // complex128, Fortran order (2, 3): column-major bytes.
        let mut body = Vec::new();
        for v in [(0.0f64, 1.0f64), (3.0, 4.0), (1.0, 2.0), (4.0, 5.0), (2.0, 3.0), (5.0, 6.0)] {
            body.extend_from_slice(&v.0.to_le_bytes());
            body.extend_from_slice(&v.1.to_le_bytes());
        }
        std::fs::write(&p, handmade("{'descr': '<c16', 'fortran_order': True, 'shape': (2, 3), }", &body)).unwrap();
        let a = read_complex(&p).unwrap();
        let re: Vec<f64> = a.data.iter().map(|c| c.re).collect();
        let im: Vec<f64> = a.data.iter().map(|c| c.im).collect();
        assert_eq!(re, vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
        assert_eq!(im, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    }

    #[test]
    fn wrong_dtypes_name_file_found_and_expected() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.npy");
        let name = p.display().to_string();
        // Real files are refused by read_complex, and complex files by read.
        write_f32(&p, &[2], false, &[1.0, 2.0]).unwrap();
        let e = read_complex(&p).unwrap_err();
        assert!(matches!(e, NpyError::NotComplex { .. }));
        let msg = e.to_string();
        assert!(msg.starts_with(&name) && msg.contains("<f4 is not complex") && msg.contains("complex64"), "{msg}");
        write_c64(&p, &[1], &[C32::new(1.0, 0.0)]).unwrap();
        let msg = read(&p).unwrap_err().to_string();
        assert!(msg.starts_with(&name) && msg.contains("dtype <c8") && msg.contains("float32"), "{msg}");
        // Unsupported scalar and structured dtypes.
        std::fs::write(&p, handmade("{'descr': '<f2', 'fortran_order': False, 'shape': (1,), }", &[0, 0])).unwrap();
        let msg = read(&p).unwrap_err().to_string();
        assert!(msg.contains("dtype <f2 is not supported; expected float32"), "{msg}");
        let msg = read_complex(&p).unwrap_err().to_string();
        assert!(msg.contains("dtype <f2 is not supported; expected complex64"), "{msg}");
        let rec = handmade("{'descr': [('a', '<f4'), ('b', '<f4')], 'fortran_order': False, 'shape': (1,), }", &[0; 8]);
        std::fs::write(&p, rec).unwrap();
        let msg = read(&p).unwrap_err().to_string();
        assert!(msg.contains("dtype [('a', '<f4'), ('b', '<f4'), ] is not supported"), "{msg}");
    }

    #[test]
    fn bad_files_give_errors_not_panics() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.npy");
        let name = p.display().to_string();
        let check = |bytes: &[u8], want: &str| {
            std::fs::write(&p, bytes).unwrap();
            for msg in [read(&p).unwrap_err().to_string(), read_complex(&p).unwrap_err().to_string()] {
                assert!(msg.starts_with(&name) && msg.contains(want), "{msg} (wanted {want})");
            }
        };
        check(b"hello world, not numpy", "magic");
        check(b"", "magic");
        check(b"\x93NUMPY\x09\x00\x10\x00{}", "unsupported version");
        // Truncated: inside the magic, inside the header, and in the data.
        check(&NUMPY_C8[..5], "magic");
        check(&NUMPY_C8[..40], "truncated header");
        check(&NUMPY_C8[..NUMPY_C8.len() - 1], "15 data bytes, shape [2] needs 16");
        check(&NUMPY_F4_C[..NUMPY_F4_C.len() - 4], "20 data bytes, shape [2, 3] needs 24");
        // The header lies about the shape: more data than the file holds, an overflowing size,
        // and nonsense.
        check(&handmade("{'descr': '<f4', 'fortran_order': False, 'shape': (1000000000000,), }", &[0; 8]), "needs");
        check(
            &handmade("{'descr': '<f8', 'fortran_order': False, 'shape': (4294967296, 4294967296, 2), }", &[0; 8]),
            "too large",
        );
        check(
            &handmade("{'descr': '<c8', 'fortran_order': False, 'shape': (4611686018427387904,), }", &[0; 8]),
            "too large",
        );
        check(&handmade("{'descr': '<f4', 'fortran_order': False, 'shape': (-1,), }", &[0; 8]), "negative");
        check(&handmade("{'descr': '<f4', 'fortran_order': False, 'shape': 'x', }", &[0; 8]), "shape");
        check(&handmade("{'descr': '<f4', 'fortran_order': False, }", &[0; 8]), "shape");
        check(&handmade("{'descr': '<f4', 'fortran_order': False, 'shape': (2,", &[0; 8]), "not a .npy file");
        check(&handmade("{'descr': 'zz', 'fortran_order': False, 'shape': (2,), }", &[0; 8]), "type");
        let deep = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {}, }}", "(".repeat(20000));
        check(&handmade(&deep, &[0; 8]), "not a .npy file");
        // A version-2 header that claims 4 GiB.
        check(b"\x93NUMPY\x02\x00\xff\xff\xff\xff{'descr'", "truncated header");
        // Garbage after a valid magic, at every length.
        for n in 0..NUMPY_F8_FORTRAN.len() {
            let mut g = NUMPY_F8_FORTRAN[..n].to_vec();
            g.extend(std::iter::repeat_n(0xA5, 7));
            std::fs::write(&p, &g).unwrap();
            assert_eq!(read(&p).is_ok(), n >= NUMPY_F8_FORTRAN.len() - 7, "{n} bytes");
        }
        assert!(matches!(read(&dir.path().join("missing.npy")), Err(NpyError::Io { .. })));
    }

    #[test]
    fn writes_check_the_shape_and_stay_atomic() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.npy");
        write_f64(&p, &[2], &[1.0, 2.0]).unwrap();
        let e = write_f64(&p, &[2, 3], &[1.0; 5]).unwrap_err();
        assert!(matches!(e, NpyError::Shape { expected: 6, got: 5, .. }), "{e}");
        assert!(e.to_string().contains("shape [2, 3] holds 6 values, but 5 were given"), "{e}");
        // The refused write left the old file alone, and no temporary file behind.
        assert_eq!(read(&p).unwrap().data, vec![1.0, 2.0]);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        assert!(matches!(write_u8(&dir.path().join("no/such/dir.npy"), &[1], &[0]), Err(NpyError::Io { .. })));
    }
}
