use rustfft::{FftPlanner, num_complex::Complex};
use std::time::Instant;
fn main() {
    for n in [100usize, 128, 200] {
        let mut p = FftPlanner::<f64>::new();
        let f = p.plan_fft_inverse(n);
        let b = 8;
        let mut a = vec![Complex::new(0.5, 0.1); n * b];
        let mut o = vec![Complex::new(0.0, 0.0); n * b];
        let mut s = vec![Complex::new(0.0, 0.0); f.get_outofplace_scratch_len()];
        let reps = 20000;
        let t = Instant::now();
        for _ in 0..reps { f.process_outofplace_with_scratch(&mut a, &mut o, &mut s); a.copy_from_slice(&o); }
        println!("n={n}: {:.1} ns per FFT", t.elapsed().as_secs_f64() * 1e9 / (reps * b) as f64);
    }
}
