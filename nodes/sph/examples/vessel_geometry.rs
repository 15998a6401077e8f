//! Builds the carotid bifurcation preset (or a geometry from a TOML file with a `[[branches]]` list)
//! at lattice spacing dx, prints the particle counts, the lumen area, the build time and the
//! minimum kernel coverage Σ (m/ρ) W of the fluid particles (quartic spline, h = 1.2 dx), and
//! optionally writes the particles as CSV (x, z, vx, vz, kind, group).
//!
//! `cargo run --release -p sonoflow-sph --example vessel_geometry -- [dx_mm] [out.csv] [geometry.toml]`
//! (`PRINT_GEOMETRY=1` also prints the geometry as TOML).

use std::io::Write;
use std::time::Instant;

use sonoflow_sph::geometry::{carotid_bifurcation, BuildOptions, InitialVelocity, VesselGeometry};
use sonoflow_sph::{CellList, Kernel, KernelKind, ParticleKind, Real};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dx: Real = args.first().map(|s| s.parse::<Real>()).transpose()?.unwrap_or(0.15) * 1e-3;
    let geom = match args.get(2) {
        Some(path) => toml::from_str::<VesselGeometry>(&std::fs::read_to_string(path)?)?,
        None => carotid_bifurcation(),
    };
    if std::env::var("PRINT_GEOMETRY").is_ok() {
        println!("{}", toml::to_string(&geom)?);
    }
    let h = 1.2 * dx;
    let opts = BuildOptions {
        dx,
        support: 2.5 * h,
        initial_velocity: InitialVelocity::FullyDeveloped,
        relax_iterations: std::env::var("RELAX").ok().and_then(|v| v.parse().ok()).unwrap_or(0),
        ..Default::default()
    };
    let t = Instant::now();
    let scene = geom.build(&opts)?;
    let took = t.elapsed().as_secs_f64();
    let p = &scene.particles;
    println!(
        "dx = {} mm: {} fluid, {} type I, {} type II ({} layers), {} reservoir; lumen {:.2} mm² (fluid {:.2} mm²); built in {:.3} s",
        dx * 1e3,
        scene.count(ParticleKind::Fluid),
        scene.count(ParticleKind::WallOn),
        scene.count(ParticleKind::WallOutside),
        scene.wall_layers,
        scene.count(ParticleKind::Buffer),
        scene.lumen_area * 1e6,
        scene.count(ParticleKind::Fluid) as Real * dx * dx * 1e6,
        took
    );
    for b in &scene.boundaries {
        println!(
            "  boundary {}: origin ({:.6}, {:.6}) mm, normal ({}, {}), half-width {} mm, mean inflow {:.4} m/s",
            b.name,
            b.origin[0] * 1e3,
            b.origin[1] * 1e3,
            b.normal[0],
            b.normal[1],
            b.half_width * 1e3,
            b.inflow.mean
        );
    }
    let kernel = Kernel::new(KernelKind::QuarticSpline, h);
    let mut cells = CellList::default();
    cells.build(&p.x, &p.z, kernel.support_radius(), None, None);
    let (mut worst, mut at) = (Real::INFINITY, 0);
    let mut hist = [0usize; 4];
    for a in 0..p.len() {
        if p.kind[a] != ParticleKind::Fluid {
            continue;
        }
        let mut sum = 0.0;
        cells.for_each_neighbour(p.x[a], p.z[a], &p.x, &p.z, |b, _, _, r2| {
            sum += p.mass[b] / p.rho[b] * kernel.w(r2.sqrt())
        });
        for (k, lim) in [0.8, 0.85, 0.9, 0.95].iter().enumerate() {
            if sum < *lim {
                hist[k] += 1;
            }
        }
        if std::env::var("COVERAGE_DUMP").is_ok() && sum < 0.9 {
            println!("    low {sum:.4} at ({:.3}, {:.3}) mm", p.x[a] * 1e3, p.z[a] * 1e3);
        }
        if sum < worst {
            (worst, at) = (sum, a);
        }
    }
    println!("  min kernel coverage {worst:.4} at ({:.3}, {:.3}) mm", p.x[at] * 1e3, p.z[at] * 1e3);
    println!("  fluid particles with coverage < 0.8, 0.85, 0.9, 0.95: {hist:?}");
    if let Some(path) = args.get(1) {
        let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
        writeln!(f, "x,z,vx,vz,kind,group")?;
        for i in 0..p.len() {
            let k = match p.kind[i] {
                ParticleKind::Fluid => 0,
                ParticleKind::WallOn => 1,
                ParticleKind::WallOutside => 2,
                ParticleKind::Buffer => 3,
            };
            writeln!(f, "{},{},{},{},{},{}", p.x[i], p.z[i], p.vx[i], p.vz[i], k, p.group[i])?;
        }
    }
    Ok(())
}
