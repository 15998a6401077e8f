use std::time::Instant;
use sonoflow_smoothn::dct::{DctN, Dct1d};
fn main() {
    let n = 200;
    let plan = DctN::new(&[n, n]);
    let mut s = plan.make_scratch();
    let x: Vec<f64> = (0..n*n).map(|i| (i as f64 * 0.37).sin()).collect();
    let mut y = vec![0.0; n*n];
    let mut z = vec![0.0; n*n];
    for _ in 0..20 { plan.forward(&x, &mut y, &mut s); plan.inverse(&y, &mut z, &mut s); }
    let r = 200;
    let t = Instant::now();
    for _ in 0..r { plan.forward(&x, &mut y, &mut s); }
    println!("forward 2D {:.1} us", t.elapsed().as_secs_f64()*1e6/r as f64);
    let t = Instant::now();
    for _ in 0..r { plan.inverse(&y, &mut z, &mut s); }
    println!("inverse 2D {:.1} us", t.elapsed().as_secs_f64()*1e6/r as f64);
    let d = Dct1d::new(n);
    let mut ls = d.make_scratch();
    let mut o = vec![0.0; n];
    let t = Instant::now();
    for i in 0..r*n { d.forward(&x[(i % n)*n..(i%n)*n+n], &mut o, &mut ls); }
    println!("1D line {:.3} us", t.elapsed().as_secs_f64()*1e6/(r*n) as f64);
    let t = Instant::now();
    for i in 0..r*n { d.inverse(&x[(i % n)*n..(i%n)*n+n], &mut o, &mut ls); }
    println!("1D line inv {:.3} us", t.elapsed().as_secs_f64()*1e6/(r*n) as f64);
}
