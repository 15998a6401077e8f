//! Element-wise kernels of the smoother with a fixed summation order: 4-lane partial sums and
//! fixed-size chunks (independent of the thread count), run on rayon threads when the `parallel`
//! feature is on. Same inputs give the same bits for any number of threads.

/// Runs `f` on every component, on rayon threads when the `parallel` feature is on. Each
/// component's arithmetic is sequential, so the result does not depend on the thread count.
pub(crate) fn for_each_component<T: Send, F: Fn(&mut T) + Sync + Send>(comps: &mut [T], f: F) {
    #[cfg(feature = "parallel")]
    if comps.len() > 1 && rayon::current_num_threads() > 1 {
        use rayon::prelude::*;
        comps.par_iter_mut().for_each(f);
        return;
    }
    comps.iter_mut().for_each(f);
}

/// Runs `f(i, chunk)` on the [`CHUNK`]-sized chunks of `out` (chunk `i` starts at `i·CHUNK`), on
/// rayon threads when enabled. Chunks are independent, so the result does not depend on the thread
/// count.
pub(crate) fn for_each_chunk<F: Fn(usize, &mut [f64]) + Sync + Send>(out: &mut [f64], f: F) {
    #[cfg(feature = "parallel")]
    if out.len() > CHUNK && rayon::current_num_threads() > 1 {
        use rayon::prelude::*;
        out.par_chunks_mut(CHUNK).enumerate().for_each(|(i, c)| f(i, c));
        return;
    }
    out.chunks_mut(CHUNK).enumerate().for_each(|(i, c)| f(i, c));
}

/// `Σ_i f(a_i, b_i)` accumulated in 4 interleaved lanes: a fixed order (deterministic) that the
/// compiler can vectorise.
#[inline(always)]
pub(crate) fn lane_sum(a: &[f64], b: &[f64], f: impl Fn(f64, f64) -> f64) -> f64 {
    let mut acc = [0.0f64; 4];
    let body = a.len() / 4 * 4;
    for (a4, b4) in a[..body].chunks_exact(4).zip(b[..body].chunks_exact(4)) {
        for l in 0..4 {
            acc[l] += f(a4[l], b4[l]);
        }
    }
    let tail: f64 = a[body..].iter().zip(&b[body..]).map(|(x, y)| f(*x, *y)).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// `Σ v` in 16 interleaved lanes (four independent vector chains, so the additions run at the
/// adders' throughput instead of their latency), combined in a fixed order.
#[inline(always)]
fn sum16(v: &[f64]) -> f64 {
    let mut acc = [0.0f64; 16];
    let body = v.len() / 16 * 16;
    for c in v[..body].chunks_exact(16) {
        for l in 0..16 {
            acc[l] += c[l];
        }
    }
    let tail: f64 = v[body..].iter().sum();
    let mut quads = [0.0f64; 4];
    for (q, quad) in quads.iter_mut().enumerate() {
        *quad = (acc[q] + acc[q + 4]) + (acc[q + 8] + acc[q + 12]);
    }
    (quads[0] + quads[1]) + (quads[2] + quads[3]) + tail
}

/// Elements per chunk of [`gamma_sums`] (fixed, so partial sums do not depend on the thread count).
pub(crate) const CHUNK: usize = 4096;

/// `Γ = 1/(1 + S Λ^m)` into `gamma`; returns `[Σ Γ, Σ power·(Γ − 1)²]` (the second 0 without
/// `power`). Chunks of [`CHUNK`] run on rayon threads when enabled; their partial sums are added in
/// chunk order, so the result is the same for any thread count.
pub(crate) fn gamma_sums(
    gamma: &mut [f64],
    lm: &[f64],
    power: Option<&[f64]>,
    s: f64,
    partials: &mut Vec<[f64; 2]>,
) -> [f64; 2] {
    let work = |i: usize, g: &mut [f64]| -> [f64; 2] {
        let range = i * CHUNK..i * CHUNK + g.len();
        let (lm, pw) = (&lm[range.clone()], power.map(|pw| &pw[range]));
        #[cfg(target_arch = "x86_64")]
        if avx2() {
            // SAFETY: the CPU supports AVX2.
            return unsafe { gamma_chunk_avx2(g, lm, pw, s) };
        }
        gamma_chunk(g, lm, pw, s)
    };
    partials.clear();
    #[cfg(feature = "parallel")]
    if gamma.len() > CHUNK && rayon::current_num_threads() > 1 {
        use rayon::prelude::*;
        gamma.par_chunks_mut(CHUNK).enumerate().map(|(i, g)| work(i, g)).collect_into_vec(partials);
    }
    if partials.is_empty() {
        partials.extend(gamma.chunks_mut(CHUNK).enumerate().map(|(i, g)| work(i, g)));
    }
    partials.iter().fold([0.0, 0.0], |acc, p| [acc[0] + p[0], acc[1] + p[1]])
}

/// One chunk of [`gamma_sums`].
#[inline(always)]
fn gamma_chunk(g: &mut [f64], lm: &[f64], power: Option<&[f64]>, s: f64) -> [f64; 2] {
    for (g, l) in g.iter_mut().zip(lm) {
        *g = 1.0 / (1.0 + s * l);
    }
    let tr = sum16(g);
    let rss = power.map_or(0.0, |pw| lane_sum(g, pw, |g, p| p * (g - 1.0) * (g - 1.0)));
    [tr, rss]
}

/// [`gamma_chunk`] compiled for AVX2 (the same operations in the same order, so the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn gamma_chunk_avx2(g: &mut [f64], lm: &[f64], power: Option<&[f64]>, s: f64) -> [f64; 2] {
    gamma_chunk(g, lm, power, s)
}

/// AVX2 available (cached by the standard library).
#[cfg(target_arch = "x86_64")]
#[inline]
fn avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

/// `z ← rf·ẑ + (1 − rf)·z`; returns `[‖z_old − z‖², ‖z‖², ‖z_old‖²]`, summed in 4 lanes.
pub(crate) fn relax(z: &mut [f64], zhat: &[f64], rf: f64) -> [f64; 3] {
    #[cfg(target_arch = "x86_64")]
    if avx2() {
        // SAFETY: the CPU supports AVX2.
        return unsafe { relax_avx2(z, zhat, rf) };
    }
    relax_body(z, zhat, rf)
}

/// [`relax`] compiled for AVX2 (the same operations in the same order, so the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn relax_avx2(z: &mut [f64], zhat: &[f64], rf: f64) -> [f64; 3] {
    relax_body(z, zhat, rf)
}

#[inline(always)]
fn relax_body(z: &mut [f64], zhat: &[f64], rf: f64) -> [f64; 3] {
    // 16 lanes per sum (four vector chains each, so the additions run at the adders' throughput),
    // combined in a fixed order.
    let mut acc = [[0.0f64; 16]; 3];
    let step = |zold: f64, zhat: f64, acc: &mut [[f64; 16]; 3], l: usize| {
        let znew = rf * zhat + (1.0 - rf) * zold;
        acc[0][l] += (zold - znew) * (zold - znew);
        acc[1][l] += znew * znew;
        acc[2][l] += zold * zold;
        znew
    };
    let body = z.len() / 16 * 16;
    for (z16, h16) in z[..body].chunks_exact_mut(16).zip(zhat[..body].chunks_exact(16)) {
        for l in 0..16 {
            z16[l] = step(z16[l], h16[l], &mut acc, l);
        }
    }
    for i in body..z.len() {
        z[i] = step(z[i], zhat[i], &mut acc, i % 16);
    }
    acc.map(|a| {
        let q = |k: usize| (a[k] + a[k + 4]) + (a[k + 8] + a[k + 12]);
        (q(0) + q(1)) + (q(2) + q(3))
    })
}
