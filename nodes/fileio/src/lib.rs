//! Files that other programs read: atomic writes and `.npy` arrays.
//!
//! * [`write_atomic`]: a reader sees the old file or the new one, never half of it.
//! * [`npy`]: NumPy `.npy` arrays (the batch tools' input and output format).

pub mod npy;

use std::io::Write;
use std::path::Path;

/// Writes a file atomically (temporary file + rename), so no reader ever sees half of it.
pub fn write_atomic(path: &Path, data: &[u8]) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp~");
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(data)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)
}
