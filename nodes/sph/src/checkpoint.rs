//! Checkpoints: the full solver state in one file, to start a run from a saved state (skip the
//! warm-up cycles of a pulsatile flow).
//!
//! Layout (little endian): magic `SONOSPH\0`, u32 format version (1), u64 length L of a JSON
//! header, the header (time, steps, next id, particle count, boundary bookkeeping, shifting and
//! guard counters, the parameters and open boundaries the state was computed with), then the
//! particle arrays x, z, vx, vz, ρ, m (f64 each), kind (u8), id (u64), group (u16), and finally an
//! FNV-1a 64-bit checksum of all the preceding bytes. Files are written to a temporary file,
//! fsynced and renamed (with [`sonoflow_fileio::write_atomic`]), so a checkpoint on disk is never
//! half written; a truncated or corrupted file is refused with a clear error.

use std::io::Read;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::boundary::{BoundaryFlux, OpenBoundary};
use crate::params::SphParams;
use crate::particles::{ParticleKind, Particles};
use crate::Real;

const MAGIC: &[u8; 8] = b"SONOSPH\0";
const VERSION: u32 = 1;

/// Everything needed to continue a run.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpoint {
    /// Header data.
    pub header: CheckpointHeader,
    /// Particles.
    pub particles: Particles,
}

/// The JSON header of a checkpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CheckpointHeader {
    /// Simulation time \[s\].
    pub time: Real,
    /// Steps taken.
    pub steps: u64,
    /// Next id for created particles.
    pub next_id: u64,
    /// Number of particles.
    pub n_particles: u64,
    /// dt of the first step (reference of the dt-collapse criterion).
    pub first_dt: Option<Real>,
    /// Report of the last step (its dt shapes the next steps towards an output time).
    pub last_step: Option<crate::step::StepReport>,
    /// Mass bookkeeping per open boundary.
    pub fluxes: Vec<BoundaryFlux>,
    /// Shifting bookkeeping so far: Σ |δr_shift|² and Σ |u Δt|² over fluid particles and steps
    /// (their ratio is [`crate::Diagnostics::shift_ratio`]). Absent in files written before it was
    /// added: (0, 0).
    #[serde(default)]
    pub shift_sums: (Real, Real),
    /// Anti-penetration guard corrections so far ([`crate::Diagnostics::guard_corrections`]).
    /// Absent in files written before it was added: 0.
    #[serde(default)]
    pub guard_corrections: u64,
    /// Parameters of the run that wrote it.
    pub params: SphParams,
    /// Open boundaries of the run that wrote it.
    pub boundaries: Vec<OpenBoundary>,
}

/// Checkpoint I/O errors.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// File system error.
    #[error("checkpoint `{path}`: {source}")]
    Io {
        /// The file.
        path: String,
        /// The error.
        source: std::io::Error,
    },
    /// Not a checkpoint, wrong version, truncated or corrupted.
    #[error("checkpoint `{path}` is invalid: {reason}")]
    Invalid {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
}

struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn feed(&mut self, b: &[u8]) {
        for &x in b {
            self.0 ^= x as u64;
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }
}

fn kind_code(k: ParticleKind) -> u8 {
    match k {
        ParticleKind::Fluid => 0,
        ParticleKind::WallOn => 1,
        ParticleKind::WallOutside => 2,
        ParticleKind::Buffer => 3,
    }
}

fn kind_from(c: u8) -> Option<ParticleKind> {
    Some(match c {
        0 => ParticleKind::Fluid,
        1 => ParticleKind::WallOn,
        2 => ParticleKind::WallOutside,
        3 => ParticleKind::Buffer,
        _ => return None,
    })
}

impl Checkpoint {
    /// Serialises to bytes (the file layout of the module documentation).
    pub fn to_bytes(&self) -> Vec<u8> {
        let p = &self.particles;
        let header = serde_json::to_vec(&self.header).unwrap_or_default();
        let mut out = Vec::with_capacity(64 + header.len() + p.len() * 67);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(header.len() as u64).to_le_bytes());
        out.extend_from_slice(&header);
        for v in [&p.x, &p.z, &p.vx, &p.vz, &p.rho, &p.mass] {
            for x in v.iter() {
                out.extend_from_slice(&x.to_le_bytes());
            }
        }
        out.extend(p.kind.iter().map(|&k| kind_code(k)));
        for id in &p.id {
            out.extend_from_slice(&id.to_le_bytes());
        }
        for g in &p.group {
            out.extend_from_slice(&g.to_le_bytes());
        }
        let mut h = Fnv::new();
        h.feed(&out);
        out.extend_from_slice(&h.0.to_le_bytes());
        out
    }

    /// Parses bytes written by [`Checkpoint::to_bytes`]; `path` names the source in errors.
    pub fn from_bytes(b: &[u8], path: &str) -> Result<Self, CheckpointError> {
        let bad = |reason: String| CheckpointError::Invalid { path: path.to_string(), reason };
        if b.len() < 28 || &b[..8] != MAGIC {
            return Err(bad("not a sonoflow SPH checkpoint (bad magic)".into()));
        }
        let version = u32::from_le_bytes([b[8], b[9], b[10], b[11]]);
        if version != VERSION {
            return Err(bad(format!("format version {version}, this build reads version {VERSION}")));
        }
        let (body, sum) = b.split_at(b.len() - 8);
        let mut h = Fnv::new();
        h.feed(body);
        let mut s8 = [0u8; 8];
        s8.copy_from_slice(sum);
        if u64::from_le_bytes(s8) != h.0 {
            return Err(bad("checksum mismatch: the file is truncated or corrupted".into()));
        }
        let mut l8 = [0u8; 8];
        l8.copy_from_slice(&b[12..20]);
        let hl = u64::from_le_bytes(l8) as usize;
        let hend = 20usize.checked_add(hl).filter(|&e| e <= body.len()).ok_or_else(|| bad("header length".into()))?;
        let header: CheckpointHeader =
            serde_json::from_slice(&body[20..hend]).map_err(|e| bad(format!("header: {e}")))?;
        let n = header.n_particles as usize;
        let need = n.checked_mul(6 * 8 + 1 + 8 + 2).ok_or_else(|| bad("particle count".into()))?;
        if body.len() - hend != need {
            return Err(bad(format!(
                "{} bytes of particle data for {n} particles, expected {need}",
                body.len() - hend
            )));
        }
        let mut off = hend;
        let mut f64s = || {
            let v: Vec<Real> = (0..n)
                .map(|i| {
                    let mut a = [0u8; 8];
                    a.copy_from_slice(&body[off + 8 * i..off + 8 * i + 8]);
                    Real::from_le_bytes(a)
                })
                .collect();
            off += 8 * n;
            v
        };
        let (x, z, vx, vz, rho, mass) = (f64s(), f64s(), f64s(), f64s(), f64s(), f64s());
        let kind = body[off..off + n]
            .iter()
            .map(|&c| kind_from(c).ok_or_else(|| bad(format!("unknown particle kind code {c}"))))
            .collect::<Result<Vec<_>, _>>()?;
        off += n;
        let id = (0..n)
            .map(|i| {
                let mut a = [0u8; 8];
                a.copy_from_slice(&body[off + 8 * i..off + 8 * i + 8]);
                u64::from_le_bytes(a)
            })
            .collect();
        off += 8 * n;
        let group = (0..n).map(|i| u16::from_le_bytes([body[off + 2 * i], body[off + 2 * i + 1]])).collect();
        Ok(Checkpoint { header, particles: Particles { x, z, vx, vz, rho, mass, kind, id, group } })
    }

    /// Writes atomically ([`sonoflow_fileio::write_atomic`]: a uniquely named temporary file in
    /// the same folder, fsync, rename, fsync of the folder).
    pub fn write(&self, path: &Path) -> Result<(), CheckpointError> {
        sonoflow_fileio::write_atomic(path, &self.to_bytes())
            .map_err(|source| CheckpointError::Io { path: path.display().to_string(), source })
    }

    /// Reads and checks a checkpoint file.
    pub fn read(path: &Path) -> Result<Self, CheckpointError> {
        let name = path.display().to_string();
        let mut b = Vec::new();
        std::fs::File::open(path)
            .and_then(|mut f| f.read_to_end(&mut b))
            .map_err(|source| CheckpointError::Io { path: name.clone(), source })?;
        Self::from_bytes(&b, &name)
    }
}
