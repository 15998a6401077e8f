//! Fixed chunks of the particle arrays for the per-particle passes of a step (predictor, corrector,
//! shifting): each chunk a disjoint mutable view of the state, processed on rayon threads when
//! `params.parallel`. The chunks depend only on the particle count, never on the threads, and
//! every reduction over them (largest error, first bad particle, sums) combines the chunks' partial
//! results in chunk order — so a step gives the same bits with any number of threads or none.

use crate::Real;

/// Particles per chunk.
pub(super) const CHUNK: usize = 1024;

/// One chunk of the mutable state: particles `start..start + x.len()`.
pub(super) struct StateChunk<'a> {
    pub(super) start: usize,
    pub(super) x: &'a mut [Real],
    pub(super) z: &'a mut [Real],
    pub(super) vx: &'a mut [Real],
    pub(super) vz: &'a mut [Real],
    pub(super) rho: &'a mut [Real],
}

/// The state cut into chunks of [`CHUNK`] particles (all slices of one length).
pub(super) fn state_chunks<'a>(
    x: &'a mut [Real],
    z: &'a mut [Real],
    vx: &'a mut [Real],
    vz: &'a mut [Real],
    rho: &'a mut [Real],
) -> Vec<StateChunk<'a>> {
    let n = x.len();
    debug_assert!([z.len(), vx.len(), vz.len(), rho.len()].iter().all(|&l| l == n));
    let mut out = Vec::with_capacity(n.div_ceil(CHUNK));
    let (mut x, mut z, mut vx, mut vz, mut rho) = (x, z, vx, vz, rho);
    let mut start = 0;
    while !x.is_empty() {
        let k = CHUNK.min(x.len());
        let (x0, x1) = x.split_at_mut(k);
        let (z0, z1) = z.split_at_mut(k);
        let (vx0, vx1) = vx.split_at_mut(k);
        let (vz0, vz1) = vz.split_at_mut(k);
        let (r0, r1) = rho.split_at_mut(k);
        out.push(StateChunk { start, x: x0, z: z0, vx: vx0, vz: vz0, rho: r0 });
        (x, z, vx, vz, rho) = (x1, z1, vx1, vz1, r1);
        start += k;
    }
    out
}

/// `f` on every chunk, the results in chunk order (rayon threads when `parallel`).
pub(super) fn map_chunks<'a, T: Send>(
    parallel: bool,
    chunks: Vec<StateChunk<'a>>,
    f: impl Fn(StateChunk<'a>) -> T + Sync + Send,
) -> Vec<T> {
    #[cfg(feature = "parallel")]
    if parallel {
        use rayon::prelude::*;
        return chunks.into_par_iter().map(f).collect();
    }
    let _ = parallel;
    chunks.into_iter().map(f).collect()
}

/// `f` on every index range of [`CHUNK`] particles of `0..n`, the results in chunk order.
pub(super) fn map_ranges<T: Send>(
    parallel: bool,
    n: usize,
    f: impl Fn(std::ops::Range<usize>) -> T + Sync + Send,
) -> Vec<T> {
    let ranges = (0..n.div_ceil(CHUNK)).map(|c| c * CHUNK..((c + 1) * CHUNK).min(n));
    #[cfg(feature = "parallel")]
    if parallel {
        use rayon::prelude::*;
        return ranges.collect::<Vec<_>>().into_par_iter().map(f).collect();
    }
    let _ = parallel;
    ranges.map(f).collect()
}
