//! Delay-and-sum on convex arrays (MUST `param.radius`): linear arrays unchanged, the element
//! geometry of MUST's `getElementPositions`, the f-number aperture by angle from the element
//! normals, a point scatterer of synthetic I/Q focusing at its position, the Doppler projection
//! on the axis, and the errors.
//!
//! The array is C5-2v-like (fc 3.57 MHz, pitch 0.508 mm, 128 elements, radius 49.57 mm: the arc
//! spans ±37.3°, its middle bulges R − h = 10.1 mm below the chord). The expected geometry is
//! written here from the arc itself (element e at angle `−(N−1)a + 2a·e` from the centre C =
//! (0, −R cos((N−1)a)), a = asin(pitch/2R)), not through the library's formula.
#![allow(clippy::unwrap_used)]

use sonoflow_beamform::testkit::{centroid, field_of, paper_das};
use sonoflow_beamform::{das_frames, Apodization, BeamformError, DasParams, DasPlan, Grid, Interpolation, TxWave, C32};

const FC: f64 = 3.57e6;
const PITCH: f64 = 0.508e-3;
const N: usize = 128;
const R: f64 = 49.57e-3;

fn c5(fnumber: f64, rx_angle: f64, apodization: Apodization) -> DasParams {
    DasParams {
        fc: FC,
        c: 1540.0,
        fs: 4.0 * FC,
        t0: 0.0,
        pitch: PITCH,
        n_elements: N,
        radius: Some(R),
        fnumber,
        rx_angle,
        interpolation: Interpolation::Linear,
        apodization,
    }
}

/// The arc, independently: (x_e, z_e, normal angle θ_e) and the apothem h.
fn arc(n: usize, pitch: f64, r: f64) -> (Vec<(f64, f64, f64)>, f64) {
    let a = (pitch / 2.0 / r).asin();
    let half = (n as f64 - 1.0) * a;
    let h = r * half.cos();
    let els = (0..n)
        .map(|e| {
            let t = -half + 2.0 * a * e as f64;
            (r * t.sin(), r * t.cos() - h, t)
        })
        .collect();
    (els, h)
}

fn bits(v: &[C32]) -> Vec<(u32, u32)> {
    v.iter().map(|c| (c.re.to_bits(), c.im.to_bits())).collect()
}

/// `radius: None` and `radius: +∞` are the same linear array: identical plans (taps, weights,
/// gradients), bit for bit, for every kind of transmit, with and without f-number and receive
/// angle.
#[test]
fn infinite_radius_is_the_linear_array_bit_for_bit() {
    let grid = Grid::spanning(-12e-3, 12e-3, 97, 2e-3, 30e-3, 113).unwrap();
    let delays: Vec<f64> = (0..128).map(|e| 1e-7 * (e as f64 / 9.0).sin().abs()).collect();
    for (f, rx, apod) in
        [(0.0, 0.0, Apodization::Boxcar), (1.5, 0.2, Apodization::Hann), (2.0, 0.0, Apodization::Boxcar)]
    {
        for tx in [
            TxWave::PlaneWave { tilt: 0.1 },
            TxWave::Focused { x0: 2e-3, z0: 20e-3 },
            TxWave::Diverging { x0: 0.0, z0: -8e-3 },
            TxWave::Delays { delays: delays.clone() },
        ] {
            let mut p = paper_das(f, rx, 20e6);
            p.apodization = apod;
            assert_eq!(p.radius, None);
            let a = DasPlan::new(&p, &tx, &grid, 900).unwrap();
            let b = DasPlan::new(&DasParams { radius: Some(f64::INFINITY), ..p.clone() }, &tx, &grid, 900).unwrap();
            let (ta, tb) = (a.taps(), b.taps());
            assert!(a.n_taps() > 10_000);
            assert_eq!(ta.0, tb.0);
            assert_eq!(ta.1, tb.1);
            assert_eq!(bits(ta.2), bits(tb.2));
            assert_eq!(bits(ta.3), bits(tb.3));
            let g =
                |p: &DasPlan| p.delay_gradient().iter().map(|g| (g[0].to_bits(), g[1].to_bits())).collect::<Vec<_>>();
            assert_eq!(g(&a), g(&b), "{tx:?}");
        }
    }
    let p = paper_das(0.0, 0.0, 20e6);
    let (xe, ze, the) = p.element_positions();
    assert!((0..128).all(|e| xe[e] == (e as f64 - 63.5) * 0.3e-3 && ze[e] == 0.0 && the[e] == 0.0));
}

/// MUST's `getElementPositions` for a C5-2v-like array: the end elements on the chord (z = 0),
/// the middle of the arc at R − h, every element on the circle x² + (z + h)² = R² and at its
/// angle, neighbours one pitch apart (the chord of the angle 2·asin(pitch/2R)), `element_x`
/// equal to the x of `element_positions`.
#[test]
fn c5_element_positions_lie_on_the_arc() {
    for n in [128usize, 127] {
        let p = DasParams { n_elements: n, ..c5(0.0, 0.0, Apodization::Boxcar) };
        let (xe, ze, the) = p.element_positions();
        let (want, h) = arc(n, PITCH, R);
        assert!((sonoflow_beamform::convex::apothem(PITCH, n, R) - h).abs() < 1e-12, "apothem {h}");
        assert!(ze[0].abs() < 1e-12 && ze[n - 1].abs() < 1e-12, "end elements at z = 0: {} {}", ze[0], ze[n - 1]);
        assert!((xe[0] + xe[n - 1]).abs() < 1e-15 && xe[n - 1] > 0.0);
        if n % 2 == 1 {
            let c = n / 2;
            assert!(xe[c].abs() < 1e-15 && (ze[c] - (R - h)).abs() < 1e-12, "centre ({}, {})", xe[c], ze[c]);
        } else {
            let a = (PITCH / 2.0 / R).asin();
            assert!((ze[n / 2] - (R * a.cos() - h)).abs() < 1e-12);
        }
        for e in 0..n {
            assert!(
                ((xe[e] * xe[e] + (ze[e] + h) * (ze[e] + h)).sqrt() - R).abs() < 1e-12,
                "element {e} off the circle"
            );
            assert!((xe[e] - want[e].0).abs() < 1e-12 && (ze[e] - want[e].1).abs() < 1e-12, "element {e}");
            assert!((the[e] - want[e].2).abs() < 1e-12 && (xe[e].atan2(ze[e] + h) - the[e]).abs() < 1e-12);
            assert_eq!(p.element_x(e).to_bits(), xe[e].to_bits());
            if e > 0 {
                let s = (xe[e] - xe[e - 1]).hypot(ze[e] - ze[e - 1]);
                let chord = 2.0 * R * (PITCH / 2.0 / R).asin().sin();
                assert!((s - chord).abs() < 1e-12 && (s - PITCH).abs() < 1e-12, "spacing {e}: {s}");
            }
        }
    }
}

/// With an f-number, a convex array's pixel uses exactly the elements whose receive direction
/// (the normal turned by the receive angle) points within atan(1/(2F)) of the pixel — read off
/// the plan's taps (traces long enough that no tap falls off), against the angle between the
/// normal and the element→pixel vector computed here with a dot product. Pixels beside and
/// above the middle of the arc included.
#[test]
fn f_number_aperture_uses_the_elements_facing_the_pixel() {
    let ns = 4000;
    let (els, h) = arc(N, PITCH, R);
    // below the middle of the arc, and beside it above that depth (outside the circle)
    let grids = [
        Grid::spanning(-60e-3, 60e-3, 49, R - h + 1e-3, 90e-3, 31).unwrap(),
        Grid::spanning(31e-3, 60e-3, 30, 0.5e-3, 12e-3, 24).unwrap(),
        Grid::spanning(-60e-3, -31e-3, 30, 0.5e-3, 12e-3, 24).unwrap(),
    ];
    let mut used = 0usize;
    for (f, rx) in [(1.5, 0.0), (1.0, 0.25), (0.7, -0.4), (0.5, 1.0)] {
        let p = c5(f, rx, Apodization::Boxcar);
        let alpha = (1.0 / (2.0 * f)).atan();
        for grid in &grids {
            let plan = DasPlan::new(&p, &TxWave::Delays { delays: vec![0.0; N] }, grid, ns).unwrap();
            let (off, idx, _, _) = plan.taps();
            for pix in 0..grid.n_pixels() {
                let (x, z) = (grid.x(pix % grid.nx), grid.z(pix / grid.nx));
                let got: Vec<usize> =
                    idx[off[pix] as usize..off[pix + 1] as usize].iter().map(|&i| i as usize / ns).collect();
                for (e, &(xe, ze, th)) in els.iter().enumerate() {
                    let (vx, vz) = (x - xe, z - ze);
                    let cos = ((th + rx).sin() * vx + (th + rx).cos() * vz) / vx.hypot(vz);
                    let ang = cos.clamp(-1.0, 1.0).acos();
                    if (ang - alpha).abs() < 1e-9 {
                        continue; // on the edge: either way
                    }
                    assert_eq!(
                        got.contains(&e),
                        ang < alpha,
                        "F {f}, rx {rx}, pixel ({x}, {z}), element {e}: angle {ang}"
                    );
                }
                used += got.len();
            }
        }
    }
    assert!(used > 10_000, "{used}");
}

/// Element-major synthetic I/Q of point scatterers: element e records, for each scatterer at
/// round-trip time τ_e, a Gaussian-enveloped pulse demodulated at fc, `exp(−((t − τ_e)/σ)²/2) ·
/// exp(−i 2π fc τ_e)` (what `Rf2Iq` makes of `env(t − τ) cos(2π fc (t − τ))`; the DAS re-modulates
/// by `exp(+i 2π fc τ)`).
fn synthetic_iq(p: &DasParams, ns: usize, taus: &[f64]) -> Vec<C32> {
    let sigma = 0.7 / p.fc;
    let wc = 2.0 * std::f64::consts::PI * p.fc;
    let mut iq = vec![C32::new(0.0, 0.0); p.n_elements * ns];
    for (e, &tau) in taus.iter().enumerate() {
        for k in 0..ns {
            let t = p.t0 + k as f64 / p.fs;
            let a = (-0.5 * ((t - tau) / sigma).powi(2)).exp();
            if a > 1e-12 {
                let ph = -wc * tau;
                iq[e * ns + k] = C32::new((a * ph.cos()) as f32, (a * ph.sin()) as f32);
            }
        }
    }
    iq
}

/// Peak of |img| refined by a parabola through the neighbours in x and in z; None on the border.
fn peak(img: &[C32], g: &Grid) -> Option<(f64, f64)> {
    let m: Vec<f64> = img.iter().map(|c| f64::from(c.norm())).collect();
    let i = (0..m.len()).max_by(|&a, &b| m[a].total_cmp(&m[b]))?;
    let (iz, ix) = (i / g.nx, i % g.nx);
    if ix == 0 || iz == 0 || ix + 1 == g.nx || iz + 1 == g.nz {
        return None;
    }
    let par = |a: f64, b: f64, c: f64| 0.5 * (a - c) / (a - 2.0 * b + c);
    let dx = par(m[i - 1], m[i], m[i + 1]);
    let dz = par(m[i - g.nx], m[i], m[i + g.nx]);
    Some((g.x(ix) + dx * g.dx, g.z(iz) + dz * g.dz))
}

/// A point scatterer of synthetic I/Q focuses at its position on a convex array: 3 depths (30,
/// 50, 70 mm below the chord) × 3 lateral positions, F = 1.5, both apodisations; all elements
/// firing together (d_TX = |s − C| − R, the distance to the arc) on the beams through the centre
/// of curvature at 0° and ±20° (also with a receive angle of 0.2 rad), and a plane wave tilted
/// by 10° (MUST's convex delays: d_TX = D + x sin θ + (z + h) cos θ − R, D the largest
/// element-to-tangent distance) at x = 0, ±15 mm. Image on a λ/20 grid (±4λ laterally, ±2λ
/// axially, to hold the steered main lobes).
///
/// Position estimates: the −3 dB main-lobe centroid of |image|² must lie within λ/10 of the
/// scatterer for both apodisations; the envelope peak (parabolic refinement in x and z) within
/// λ/10 with Hann weights. With boxcar weights the peak is not a position estimate: the lateral
/// envelope is flat over a fraction of λ, and the binary f-number aperture gains or loses an
/// element of ~35 within it (at 70 mm on the axis: 34 elements at x = 0, 35 from |x| = 0.33 λ),
/// a step of ~3 % that moves the peak by up to ~0.37 λ; it is only required within λ/2.
#[test]
fn point_scatterer_focuses_on_a_convex_array() {
    let (els, h) = arc(N, PITCH, R);
    let lambda = 1540.0 / FC;
    let ns = 2400;
    let tilt = 10f64.to_radians();
    let dmax = els.iter().map(|&(_, _, t)| R - R * (t - tilt).cos()).fold(0.0, f64::max);
    let (t_first, t_last) = (els[0].2, els[N - 1].2);
    let mut cases = Vec::new();
    for z in [30e-3, 50e-3, 70e-3] {
        for beam in [0.0f64, 20.0, -20.0] {
            let x = (z + h) * beam.to_radians().tan();
            for rx in [0.0, 0.2] {
                cases.push(("all elements", x, z, rx, TxWave::Delays { delays: vec![0.0; N] }));
            }
        }
        for x in [0.0, 15e-3, -15e-3] {
            cases.push(("plane wave 10°", x, z, 0.0, TxWave::PlaneWave { tilt }));
        }
    }
    let mut worst = [(0.0f64, 0.0f64); 2];
    for (name, xs, zs, rx, tx) in &cases {
        let (xs, zs, rx) = (*xs, *zs, *rx);
        let dtx = match tx {
            TxWave::PlaneWave { tilt } => {
                // the ray back from the scatterer against the wave meets the arc within its span
                let (s, c) = tilt.sin_cos();
                let b = xs * s + (zs + h) * c;
                let t = b - (b * b - (xs * xs + (zs + h) * (zs + h) - R * R)).sqrt();
                let (xa, za) = (xs - t * s, zs + h - t * c);
                let ang = xa.atan2(za);
                assert!(ang > t_first && ang < t_last, "{name} at ({xs}, {zs}) is not insonified by the plane front");
                dmax + xs * s + (zs + h) * c - R
            }
            _ => {
                assert!(xs.atan2(zs + h) > t_first && xs.atan2(zs + h) < t_last);
                xs.hypot(zs + h) - R
            }
        };
        for apod in [Apodization::Boxcar, Apodization::Hann] {
            let p = c5(1.5, rx, apod);
            let taus: Vec<f64> = els.iter().map(|&(xe, ze, _)| (dtx + (xs - xe).hypot(zs - ze)) / p.c).collect();
            let iq = synthetic_iq(&p, ns, &taus);
            let grid =
                Grid::spanning(xs - 4.0 * lambda, xs + 4.0 * lambda, 161, zs - 2.0 * lambda, zs + 2.0 * lambda, 81)
                    .unwrap();
            let plan = DasPlan::new(&p, tx, &grid, ns).unwrap();
            let img = plan.apply_to_vec(&iq).unwrap();
            let (x, z) = peak(&img, &grid).expect("peak inside the grid");
            let (ex, ez) = ((x - xs) / lambda, (z - zs) / lambda);
            let (cx, cz) = centroid(&img, &grid).expect("main lobe inside the grid");
            let (cx, cz) = ((cx - xs) / lambda, (cz - zs) / lambda);
            println!(
                "{name}, rx {rx}, {apod:?}, scatterer ({:+.1}, {:.1}) mm: error x {ex:+.4} λ, z {ez:+.4} λ; centroid {cx:+.4} {cz:+.4}",
                xs * 1e3,
                zs * 1e3
            );
            // the −3 dB centroid, both apodisations; the peak with Hann weights (see above)
            assert!(cx.hypot(cz) < 0.1, "{name} {apod:?} rx {rx} at ({xs}, {zs}): centroid ({cx:.3}, {cz:.3}) λ");
            let bound = if apod == Apodization::Hann { 0.1 } else { 0.5 };
            assert!(ex.hypot(ez) < bound, "{name} {apod:?} rx {rx} at ({xs}, {zs}): peak ({ex:.3}, {ez:.3}) λ");
            let w = &mut worst[usize::from(apod == Apodization::Hann)];
            w.0 = w.0.max(ex.hypot(ez));
            w.1 = w.1.max(cx.hypot(cz));
        }
    }
    println!(
        "worst focusing errors over {} scatterer positions (peak, −3 dB centroid): boxcar {:.4} λ, {:.4} λ; \
         Hann {:.4} λ, {:.4} λ",
        cases.len(),
        worst[0].0,
        worst[0].1,
        worst[1].0,
        worst[1].1
    );
}

/// On the axis of a symmetric convex array with a symmetric transmit, the Doppler projection
/// points along z: its x component vanishes (1e-6) and it is ≈ −(1 + mean cos)/2 along z.
#[test]
fn projection_on_the_axis_points_along_z() {
    let grid = Grid { x0: -2e-3, z0: 39e-3, dx: 1e-3, dz: 1e-3, nx: 5, nz: 3 };
    let pix = grid.nx + 2;
    assert_eq!((grid.x(2), grid.z(1)), (0.0, 40e-3));
    for (f, apod) in [(1.5, Apodization::Boxcar), (1.5, Apodization::Hann), (0.0, Apodization::Boxcar)] {
        for tx in [TxWave::Delays { delays: vec![0.0; N] }, TxWave::PlaneWave { tilt: 0.0 }] {
            let p = c5(f, 0.0, apod);
            let plan = DasPlan::new(&p, &tx, &grid, 3000).unwrap();
            let a = plan.projection()[pix];
            assert!(a[0].abs() < 1e-6, "F {f} {apod:?} {tx:?}: projection {a:?}");
            assert!(a[1] < -0.85 && a[1] > -1.0, "F {f} {apod:?}: projection {a:?}");
            // right of the axis, it leans to −x (back towards the centre of curvature)
            let b = plan.projection()[pix + 2];
            assert!(b[0] < 0.0, "{b:?}");
        }
    }
}

/// Bad radii, too many elements for the arc and grids through the face give errors naming the
/// field; a receive angle is allowed on a convex array; serde reads MUST's `radius`.
#[test]
fn convex_errors_name_the_field() {
    let g = Grid::spanning(-10e-3, 10e-3, 11, 20e-3, 40e-3, 11).unwrap();
    let tx = TxWave::PlaneWave { tilt: 0.0 };
    let err = |p: &DasParams, g: &Grid| field_of(DasPlan::new(p, &tx, g, 3000).unwrap_err());
    for r in [0.0, -1.0, f64::NAN, f64::NEG_INFINITY, 2e6] {
        let p = DasParams { radius: Some(r), ..c5(1.5, 0.0, Apodization::Boxcar) };
        assert_eq!(err(&p, &g), "das.radius", "radius {r}");
        assert_eq!(field_of(p.validate().unwrap_err()), "das.radius");
    }
    // 10 mm radius, pitch 0.508 mm: (N − 1)·asin(pitch/2R) < π/2 up to N = 62
    let small = |n: usize| DasParams { radius: Some(10e-3), n_elements: n, ..c5(1.5, 0.0, Apodization::Boxcar) };
    let e = DasPlan::new(&small(63), &tx, &g, 3000).unwrap_err();
    assert!(e.to_string().contains("at most 62 elements"), "{e}");
    assert_eq!(field_of(e), "das.n_elements");
    assert!(DasPlan::new(&small(62), &tx, &g, 3000).is_ok());
    let tiny = |n: usize| DasParams { radius: Some(0.2e-3), n_elements: n, ..c5(0.0, 0.0, Apodization::Boxcar) };
    // the pitch is a chord of the arc: never wider than the diameter, whatever the count
    assert_eq!(field_of(tiny(2).validate().unwrap_err()), "das.pitch");
    assert_eq!(field_of(tiny(1).validate().unwrap_err()), "das.pitch");
    // beside the arc but behind its chord (z < 0: MUST's isOUT), refused for any array
    let below = Grid { x0: 40e-3, z0: -1e-3, dx: 1e-3, dz: 1e-3, nx: 3, nz: 3 };
    assert_eq!(err(&c5(1.5, 0.0, Apodization::Boxcar), &below), "grid.z0");
    // a grid through the face (the arc bulges to 10.1 mm at x = 0), for the plan and the frames
    let p = c5(1.5, 0.0, Apodization::Boxcar);
    let through = Grid::spanning(-10e-3, 10e-3, 11, 0.0, 20e-3, 11).unwrap();
    let e = DasPlan::new(&p, &tx, &through, 3000).unwrap_err();
    match &e {
        BeamformError::InvalidParameter { field: "grid", value, .. } => {
            assert!(value.contains("behind") && value.contains("face depth"), "{e}");
        }
        other => panic!("{other:?}"),
    }
    let frames = vec![C32::new(0.0, 0.0); N * 3000];
    assert_eq!(field_of(das_frames(&p, &tx, &through, 3000, &frames, 1).unwrap_err()), "grid");
    // a pixel beside the arc but inside its circle; and a grid beside the arc, outside it
    let beside = Grid { x0: 29e-3, z0: 0.0, dx: 1e-3, dz: 1e-3, nx: 1, nz: 1 };
    assert_eq!(err(&p, &beside), "grid");
    let outside = Grid { x0: 40e-3, z0: 0.0, dx: 1e-3, dz: 1e-3, nx: 20, nz: 20 };
    assert!(DasPlan::new(&p, &tx, &outside, 3000).is_ok());
    // receive angles are allowed on a convex array
    assert!(DasPlan::new(&c5(1.5, 0.3, Apodization::Hann), &tx, &g, 3000).is_ok());
    // serde: MUST's `radius`, omitted for a linear array
    let q: DasParams =
        serde_json::from_str(r#"{"fc":3.57e6,"fs":1.428e7,"pitch":5.08e-4,"Nelements":128,"radius":0.04957}"#).unwrap();
    assert_eq!(q.radius, Some(0.04957));
    assert!(!serde_json::to_string(&paper_das(1.0, 0.0, 20e6)).unwrap().contains("radius"));
    assert!(serde_json::to_string(&q).unwrap().contains("\"radius\":0.04957"));
}

/// The convex geometry lives in two crates (sonoflow-beamform may not depend on sonoflow-simus
/// outside its test kit): both copies give the same element positions, normals and transmit
/// delay laws, bit for bit, on C5-2v and a 20 mm radius, so SIMUS and the beamformer never
/// disagree on where an element is.
#[test]
fn simus_and_beamform_share_the_convex_geometry() {
    use sonoflow_simus::{Probe, Transmit};
    for (radius, n) in [(0.04957, 128usize), (0.02, 96)] {
        let probe = Probe { radius: Some(radius), n_elements: n, ..Probe::preset("C5-2v").unwrap() };
        let p = DasParams { radius: Some(radius), n_elements: n, ..c5(1.5, 0.0, Apodization::Boxcar) };
        let (xe, ze, the) = p.element_positions();
        for (e, q) in probe.element_positions().iter().enumerate() {
            assert_eq!((q.x, q.z, q.theta), (xe[e], ze[e], the[e]), "radius {radius}, element {e}");
        }
        for tilt in [0.0f64, 0.17, -0.3] {
            let a = Transmit::plane_wave(&probe, p.c, tilt).unwrap().delays;
            let b = TxWave::PlaneWave { tilt }.delays(&p).unwrap();
            let worst = a.iter().zip(&b).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(worst <= 1e-18, "radius {radius}, tilt {tilt}: {worst:e} s");
        }
    }
}
