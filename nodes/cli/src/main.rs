use clap::{Parser, Subcommand};
use sonoflow_launcher::launch::{self, Overrides};
use sonoflow_node_kit::KindSpec;
use std::path::PathBuf;

/// sonoflow — ultrasound flow imaging simulation as a graph of processes.
#[derive(Parser)]
#[command(version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Check a launch file and run its graph.
    Run {
        /// Launch file (TOML), e.g. launch/quickstart.toml.
        file: PathBuf,
        /// Override a parameter: NODE.PARAM[.SUB]=VALUE (TOML value; repeatable).
        #[arg(long = "set", value_name = "NODE.PARAM=VALUE")]
        set: Vec<String>,
        /// Select a node variant: NODE=VARIANT (repeatable).
        #[arg(long = "swap", value_name = "NODE=VARIANT")]
        swap: Vec<String>,
        /// Output folder (default `runs/<graph>-<date-time>`).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Service prefix of this run (default: unique per run).
        #[arg(long)]
        run_id: Option<String>,
        /// Only print errors, the recording and the report path.
        #[arg(long, short)]
        quiet: bool,
        /// Watch the run live in Foxglove: adds a `live-view` node named `live` that serves the
        /// picture topics over Foxglove's WebSocket protocol at ADDR (HOST:PORT, default
        /// 127.0.0.1:8765; `:0` picks a free port). Its parameters: `--set live.linger_s=30`, ….
        #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:8765")]
        live: Option<String>,
    },
    /// Check a launch file without starting anything.
    Check {
        file: PathBuf,
        #[arg(long = "set", value_name = "NODE.PARAM=VALUE")]
        set: Vec<String>,
        #[arg(long = "swap", value_name = "NODE=VARIANT")]
        swap: Vec<String>,
    },
    /// List the built-in node kinds and their ports.
    Kinds,
    /// Run one node process (started by `sonoflow run`, configured by SONOFLOW_NODE_CONFIG).
    #[command(hide = true)]
    Node { kind: String },
    /// Summarise an MCAP recording (topics, counts, completeness, counters).
    Inspect {
        file: PathBuf,
        /// Also read every record: decompress every chunk and check its CRC, decode every message,
        /// compare the counts with the summary; exit status 1 if anything is wrong.
        #[arg(long)]
        verify: bool,
    },
    /// Rewrite a truncated recording (recorder killed) into a complete MCAP file.
    Recover { input: PathBuf, output: PathBuf },
    /// Remove shared-memory resources left by killed processes.
    Clean,
    /// SIMUS batch tool: scatterers + MUST parameters → RF (.npy) and a JSON sidecar.
    Simus(sonoflow_tools::simus::SimusArgs),
    /// Pressure field of one transmit (MUST `pfield`) on a grid → RMS pressure .npy (nz, nx).
    Pfield(sonoflow_tools::pfield::PfieldArgs),
    /// Speckle phantom (MUST `genscat`, seeded, with inclusions) → scatterers .npy (n, 3) for `simus`.
    Genscat(sonoflow_tools::simus::GenscatArgs),
    /// Run a scene over a grid of settings; error (from its evaluator) against run time, Pareto front.
    Sweep(sonoflow_tools::sweep::SweepCmd),
    /// Smoothn batch tool: robust unsupervised smoothing of a (components, ny, nx) or (ny, nx) .npy field.
    Smoothn(sonoflow_tools::smoothn::SmoothnArgs),
    /// RF → I/Q batch tool: (n_samples, n_elements) RF .npy + MUST parameters → complex64 I/Q .npy.
    Rf2iq(sonoflow_tools::beamform::Rf2IqArgs),
    /// Delay-and-sum batch tool: (n_samples, n_elements) I/Q .npy → complex64 (nz, nx) image .npy.
    Das(sonoflow_tools::beamform::DasArgs),
    /// Colour Doppler batch tool (MUST `iq2doppler`): (nz, nx, n_frames) packet .npy → velocity,
    /// power, variance, flags .npy.
    #[command(name = "iq2doppler", alias = "doppler")]
    Iq2doppler(sonoflow_tools::beamform::DopplerArgs),
    /// B-mode batch tool (MUST `bmode`, optionally after `tgc`): I/Q .npy (depth first) → uint8
    /// .npy of the same shape, optionally a PNG.
    Bmode(sonoflow_tools::bmode::BmodeArgs),
    /// Platelet suspension (paper 2): resolved Stokes training data, network training.
    Platelet {
        #[command(subcommand)]
        what: sonoflow_tools::platelet::PlateletCmd,
    },
    /// Stability matrix: run the stiff and extreme cases of every stage, print case → outcome.
    Stability(sonoflow_stability::StabilityArgs),
    /// Benchmarks (write a Markdown table).
    Bench {
        #[command(subcommand)]
        what: sonoflow_tools::bench::BenchCmd,
    },
    /// Receiving process of `sonoflow bench transport`.
    #[command(hide = true)]
    BenchPeer(sonoflow_tools::bench::PeerArgs),
}

fn main() {
    let cli = Cli::parse();
    if !matches!(cli.cmd, Cmd::Node { .. }) {
        restore_default_sigpipe();
    }
    let code = match real_main(cli) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("sonoflow: error: {e:#}");
            1
        }
    };
    std::process::exit(code);
}

fn real_main(cli: Cli) -> anyhow::Result<i32> {
    let registry: &'static [KindSpec] = sonoflow_builtin::registry();
    match cli.cmd {
        Cmd::Run { file, set, swap, out, run_id, quiet, live } => {
            let mut add_nodes = Vec::new();
            if let Some(addr) = live {
                if let Err(e) = sonoflow_live::parse_addr(&addr) {
                    anyhow::bail!("--live: {e}");
                }
                let mut params = toml::Table::new();
                params.insert("addr".into(), toml::Value::String(addr));
                let kind = Some(sonoflow_builtin::live_view::SPEC.name.to_string());
                add_nodes.push(("live".to_string(), launch::NodeDecl { kind, params, ..Default::default() }));
            }
            let ov = Overrides { set, swap, lenient_files: false, add_nodes };
            let g = match launch::load(&file, &ov, registry) {
                Ok(g) => g,
                Err(errs) => return Ok(print_errors(&errs)),
            };
            for w in &g.warnings {
                eprintln!("sonoflow: warning: {w}");
            }
            let out_dir = out.unwrap_or_else(|| sonoflow_launcher::default_out_dir(&g.graph.name));
            let run_id = run_id.unwrap_or_else(|| sonoflow_launcher::new_run_id(&g.graph.name));
            sonoflow_launcher::run_graph(&g, &sonoflow_launcher::RunOptions { out_dir, run_id, quiet })
        }
        Cmd::Check { file, set, swap } => {
            match launch::load(&file, &Overrides { set, swap, lenient_files: true, ..Default::default() }, registry) {
                Ok(g) => {
                    for w in &g.warnings {
                        println!("warning: {w}");
                    }
                    println!(
                        "{}: ok — {} node(s), {} topic(s), {:.1} MB shared memory",
                        file.display(),
                        g.nodes.len(),
                        g.topics.len(),
                        g.shm_bytes as f64 / 1e6
                    );
                    Ok(0)
                }
                Err(errs) => Ok(print_errors(&errs)),
            }
        }
        Cmd::Kinds => {
            for k in registry {
                println!("{} — {}", k.name, k.about);
                for p in k.ports {
                    println!(
                        "    {} {} : {}{}",
                        p.dir.word(),
                        p.name,
                        p.message_type,
                        if p.required { "" } else { " (optional)" }
                    );
                }
            }
            Ok(0)
        }
        Cmd::Node { kind } => {
            let spec = registry.iter().find(|k| k.name == kind).ok_or_else(|| {
                let names: Vec<&str> = registry.iter().map(|k| k.name).collect();
                anyhow::anyhow!("unknown node kind `{kind}` (built-in: {})", names.join(", "))
            })?;
            let kit = sonoflow_node_kit::Kit::from_env()?;
            match (spec.run)(kit) {
                Ok(()) => Ok(0),
                Err(e) => {
                    eprintln!("error: {e:#}");
                    Ok(1)
                }
            }
        }
        Cmd::Inspect { file, verify } => sonoflow_tools::recording::inspect(&file, verify),
        Cmd::Recover { input, output } => sonoflow_tools::recording::recover(&input, &output),
        Cmd::Clean => {
            let n = sonoflow_node_kit::cleanup_dead_nodes()?;
            println!("removed the resources of {n} dead node(s)");
            Ok(0)
        }
        Cmd::Simus(a) => sonoflow_tools::simus::run_simus(&a),
        Cmd::Smoothn(a) => sonoflow_tools::smoothn::run_smoothn(&a),
        Cmd::Sweep(a) => sonoflow_tools::sweep::run_sweep(&a, registry),
        Cmd::Rf2iq(a) => sonoflow_tools::beamform::run_rf2iq(&a),
        Cmd::Das(a) => sonoflow_tools::beamform::run_das(&a),
        Cmd::Iq2doppler(a) => sonoflow_tools::beamform::run_iq2doppler(&a),
        Cmd::Pfield(a) => sonoflow_tools::pfield::run_pfield(&a),
        Cmd::Genscat(a) => sonoflow_tools::simus::run_genscat(&a),
        Cmd::Bmode(a) => sonoflow_tools::bmode::run_bmode(&a),
        Cmd::Stability(a) => sonoflow_stability::run(&a),
        Cmd::Platelet { what } => sonoflow_tools::platelet::run_platelet(&what),
        Cmd::Bench { what } => sonoflow_tools::bench::run_bench(what, registry),
        Cmd::BenchPeer(args) => sonoflow_tools::bench::run_peer(args),
    }
}

/// Lets a closed stdout end the program quietly, like any Unix tool: `sonoflow inspect rec.mcap |
/// head` then exits by SIGPIPE (status 141 in the shell) instead of panicking with "failed printing
/// to stdout: Broken pipe". Rust ignores SIGPIPE by default, which turns every `println!` to a
/// closed pipe into a panic; the default action covers all output of all subcommands at once.
///
/// Not for `sonoflow node`: a node's stdout and stderr are pipes that the launcher reads, and if
/// one went away mid-run a node killed outright by SIGPIPE would leave, say, a recording without
/// its summary. There Rust's default stays: the write fails (a `println!` panics and unwinds,
/// running destructors such as the recorder's finishing of its file). Processes that a
/// subcommand starts are unaffected either way: Rust's `Command` restores the default SIGPIPE
/// action before `exec`, and a Rust program (`sonoflow node`) ignores it again at start-up.
fn restore_default_sigpipe() {
    // SAFETY: signal(2) with SIG_DFL, called once at start-up before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn print_errors(errs: &[String]) -> i32 {
    for e in errs {
        eprintln!("error: {e}");
    }
    eprintln!("{} problem(s) found; nothing was started", errs.len());
    2
}
