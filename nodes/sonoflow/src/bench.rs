//! Benchmarks (placeholder, filled below).
#[derive(clap::Subcommand, Debug)]
pub enum BenchCmd {
    /// Transport cost per frame: iceoryx2 in place vs memcpy vs Unix socket.
    Transport,
}
pub fn run(_c: BenchCmd) -> anyhow::Result<i32> {
    Ok(0)
}
