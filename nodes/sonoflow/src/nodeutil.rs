//! Small helpers shared by the built-in nodes.

use iceoryx2::prelude::ipc;
use iceoryx2::sample::Sample;
use sonoflow_messages::WireMessage;
use sonoflow_node_kit::{is_eos, Input, Kit, KitError};
use std::io::Write;
use std::path::Path;
use std::time::Duration;

/// What a message handler wants next.
pub enum Flow {
    Continue,
    Stop,
}

/// Runs `f` on every message of `input` until end of stream, a stop from `f`, or a
/// termination request. Blocks on the input's event between messages (no polling).
/// Returns true if the stream ended normally (end-of-stream seen).
pub fn for_each<M, F>(kit: &mut Kit, input: &mut Input<M>, mut f: F) -> anyhow::Result<bool>
where
    M: WireMessage,
    F: FnMut(&mut Kit, &Sample<ipc::Service, [M::Elem], M::Header>) -> anyhow::Result<Flow>,
{
    loop {
        while let Some(sample) = input.try_receive()? {
            if is_eos::<M>(sample.user_header()) {
                return Ok(true);
            }
            if let Flow::Stop = f(kit, &sample)? {
                return Ok(false);
            }
        }
        match kit.check_termination() {
            Ok(()) => {}
            Err(KitError::Terminated) => return Ok(false),
            Err(e) => return Err(e.into()),
        }
        input.wait(Duration::from_millis(200))?;
    }
}

/// Writes a file atomically (temporary file + rename), so no reader ever sees half of it.
pub fn write_atomic(path: &Path, data: &[u8]) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp~");
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(data)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)
}
