//! Transmitted pulse and probe response (MUST `utils.getPulseSpectrumFunction`,
//! `getProbeFunction`, `getpulse`; pymust-notes §3–4).
//!
//! * Windowed-sine pulse of `TXnow` cycles **centred on t = 0**, spectrum
//!   `P(ω) = i·(sinc(T(ω−ωc)/2) − sinc(T(ω+ωc)/2))`, `T = TXnow/fc`, `sinc(x) = sin x / x`.
//!   P is purely imaginary: no group delay, so RF time zero is the instant the centre of the
//!   pulse leaves an element with zero delay.
//! * One-way probe (PZT + lens) response, a generalised-normal window:
//!   `H(ω) = sqrt(exp(−(|ω−ωc| / (ωB/2 / ln2^(1/p)))^p))`, `ωB = bandwidth/100·ωc`,
//!   `p = ln 126 / ln(2ωc/ωB)`; `bandwidth` is the pulse-echo −6 dB fractional bandwidth.
//! * [`PulseModel::two_way_pulse_duration`] ports `getpulse(param, 2)` (1 ns grid) — SIMUS only uses the
//!   time of its last sample to pad the maximal distance of the frequency grid.

use std::f64::consts::PI;
use std::sync::Mutex;

/// Pulse and probe spectra of one probe configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PulseModel {
    fc: f64,
    tx_now: f64,
    bandwidth: f64,
}

/// `sin(x)/x` with the exact limit 1 at 0 (numpy `np.sinc(x/π)`).
fn sinc(x: f64) -> f64 {
    if x == 0.0 {
        1.0
    } else {
        x.sin() / x
    }
}

impl PulseModel {
    /// `fc` in Hz, `tx_now` cycles, `bandwidth` in % (pulse-echo, −6 dB).
    pub fn new(fc: f64, tx_now: f64, bandwidth: f64) -> Self {
        Self { fc, tx_now, bandwidth }
    }

    /// Transmitted pulse spectrum `P(ω)` at angular frequency `w` (rad/s): the imaginary part
    /// (the real part is zero).
    pub fn pulse_im(&self, w: f64) -> f64 {
        let t = self.tx_now / self.fc;
        let wc = 2.0 * PI * self.fc;
        sinc(t * (w - wc) / 2.0) - sinc(t * (w + wc) / 2.0)
    }

    /// One-way probe response `H(ω)` (real, ≥ 0).
    pub fn probe(&self, w: f64) -> f64 {
        let wc = 2.0 * PI * self.fc;
        let wb = self.bandwidth * wc / 100.0;
        let p = 126f64.ln() / (2.0 * wc / wb).ln();
        let hsq = (-((w - wc).abs() / (wb / 2.0 / 2f64.ln().powf(1.0 / p))).powf(p)).exp();
        hsq.sqrt()
    }

    /// Duration (s) of MUST's two-way pulse: `t[-1]` of `getpulse(param, 2)`, i.e. the time of
    /// the last sample of the part of the pulse-echo waveform above 1/1023 of its maximum,
    /// computed on PyMUST's 1-ns grid with the same FFT sizes.
    ///
    /// Memoised per process (the last 16 configurations): the 1-ns grid makes it a ~4 ms
    /// computation, which a Python caller building a new [`crate::Simus`] per call would pay
    /// every time. A pure function of `(fc, tx_now, bandwidth)`, so the cache returns the same bits.
    pub fn two_way_pulse_duration(&self) -> f64 {
        static CACHE: Mutex<Vec<([u64; 3], f64)>> = Mutex::new(Vec::new());
        let key = [self.fc.to_bits(), self.tx_now.to_bits(), self.bandwidth.to_bits()];
        // a poisoned lock only means another thread panicked while holding it; the entries it
        // holds are complete (pushed whole)
        if let Some(&(_, t)) = CACHE.lock().unwrap_or_else(|e| e.into_inner()).iter().find(|(k, _)| *k == key) {
            return t;
        }
        let t = two_way_pulse_duration(self);
        let mut cache = CACHE.lock().unwrap_or_else(|e| e.into_inner());
        if cache.len() >= 16 {
            cache.remove(0);
        }
        cache.push((key, t));
        t
    }
}

/// See [`PulseModel::two_way_pulse_duration`].
fn two_way_pulse_duration(model: &PulseModel) -> f64 {
    let dt = 1e-9;
    let df = model.fc / model.tx_now / 32.0;
    // utils.nextpow2: smallest i >= 1 with 2^i >= n
    let target = 1.0 / dt / 2.0 / df;
    let mut p = 1u32;
    while ((1u64 << p) as f64) < target && p < 40 {
        p += 1;
    }
    let nf = 1usize << p.min(26);
    let fmax = 1.0 / dt / 2.0;
    let n = 2 * (nf - 1);
    let mut spectrum: Vec<num_complex::Complex<f64>> = (0..nf)
        .map(|k| {
            // np.linspace(0, fmax, nf)
            let f = if k == nf - 1 { fmax } else { k as f64 * (fmax / (nf - 1) as f64) };
            let w = 2.0 * PI * f;
            let h = model.probe(w);
            num_complex::Complex::new(0.0, model.pulse_im(w) * h * h)
        })
        .collect();
    // irfft ignores the imaginary parts of the DC and Nyquist bins
    spectrum[0].im = 0.0;
    spectrum[nf - 1].im = 0.0;
    let mut planner = realfft::RealFftPlanner::<f64>::new();
    let c2r = planner.plan_fft_inverse(n);
    let mut pulse = vec![0.0; n];
    if c2r.process(&mut spectrum, &mut pulse).is_err() {
        return 0.0;
    }
    // fftshift (n even): element j moves to (j + n/2) mod n
    pulse.rotate_left(n / 2);
    let peak = pulse.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if peak == 0.0 {
        return 0.0;
    }
    let thr = 1.0 / 1023.0;
    let first = pulse.iter().position(|v| v / peak > thr);
    let last = pulse.iter().rposition(|v| v / peak > thr);
    let (Some(idx1), Some(idx2)) = (first, last) else {
        return 0.0;
    };
    // idx = min(idx1 + 1, 2 Nf - 1 - idx2 - 1); pulse[-idx : idx-2 : -1] has n - 2 idx + 2 samples
    let idx = (idx1 + 1).min(2 * nf - 2 - idx2);
    let len = (n + 2).saturating_sub(2 * idx);
    len.saturating_sub(1) as f64 * dt
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_two_way_pulse_duration_matches_pymust() {
        // pymust-notes §4: getpulse(param, 2) of the paper probe has 2922 samples => 2.921 us.
        let m = PulseModel::new(5e6, 6.0, 75.0);
        let t = m.two_way_pulse_duration();
        assert!((t - 2.921e-6).abs() < 0.5e-9, "{t}");
        // getpulse(getparam('L11-5v'), 2): 1422 samples; P4-2v: 3638 samples (TXnow = 1)
        let t = PulseModel::new(7.6e6, 1.0, 77.0).two_way_pulse_duration();
        assert!((t - 1.421e-6).abs() < 0.5e-9, "{t}");
        let t = PulseModel::new(2.72e6, 1.0, 74.0).two_way_pulse_duration();
        assert!((t - 3.637e-6).abs() < 0.5e-9, "{t}");
    }

    #[test]
    fn memoised_pulse_duration_is_the_computed_one() {
        let check = |m: PulseModel| {
            let direct = two_way_pulse_duration(&m);
            assert_eq!(m.two_way_pulse_duration().to_bits(), direct.to_bits(), "{m:?}");
            assert_eq!(m.two_way_pulse_duration().to_bits(), direct.to_bits(), "{m:?} (cached)");
        };
        // more configurations than the cache holds, each asked twice, then the first ones again
        // (evicted by then): every answer is the computed one
        let models: Vec<PulseModel> = (0..20)
            .map(|i| PulseModel::new(3e6 + f64::from(i) * 2e5, 1.0 + f64::from(i % 3), 60.0 + f64::from(i)))
            .collect();
        models.iter().for_each(|m| check(*m));
        models[..3].iter().for_each(|m| check(*m));
    }

    #[test]
    fn probe_response_is_minus_6db_two_way_at_band_edges() {
        // bandwidth = pulse-echo -6 dB fractional bandwidth: H^2 = 1/2 at fc (1 ± bw/200)
        let m = PulseModel::new(5e6, 6.0, 75.0);
        for f in [5e6 * (1.0 - 0.375), 5e6 * (1.0 + 0.375)] {
            let h2 = m.probe(2.0 * PI * f).powi(2);
            assert!((h2 - 0.5).abs() < 1e-12, "{h2}");
        }
        assert!((m.probe(2.0 * PI * 5e6) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn pulse_spectrum_peaks_near_fc() {
        let m = PulseModel::new(5e6, 6.0, 75.0);
        let at = |f: f64| m.pulse_im(2.0 * PI * f).abs();
        assert!(at(5e6) > at(4.5e6) && at(5e6) > at(5.5e6));
        // first zeros of sinc(T(w-wc)/2) at f = fc ± fc/TXnow (up to the small negative-frequency term)
        assert!(at(5e6 + 5e6 / 6.0) < 0.02 * at(5e6));
    }
}
