//! Wire types of every sonoflow topic — the single source of truth for what crosses the graph.
//!
//! Every message is a small fixed `#[repr(C)]` **header** plus a **payload slice** of one
//! element type (iceoryx2 `publish_subscribe::<[Elem]>().user_header::<Header>()`), written in
//! place in shared memory by the producer. Every header starts with [`MsgHeaderV1`] (sequence
//! number, time of validity, frame id, flags …). Major versions live in the type names (`…V1`):
//! iceoryx2 refuses to connect a publisher and a subscriber whose type names differ, so a layout
//! change can never be misread silently. `tests/layout.rs` pins every size and offset.
//!
//! The same bytes are the MCAP record: [`cdr`] writes a header and payload as a ROS 2 CDR message
//! whose `ros2msg` schema text is generated from the Rust struct definitions, so Foxglove, the
//! Python `mcap-ros2-support` decoder and plain numpy (fixed offsets, documented in the README)
//! all read the same file. [`viz`] adds Foxglove well-known schemas (PointCloud, Grid, RawImage)
//! for pictures.
//!
//! Conventions: SI units; x lateral (m), z depth (m, positive into the medium, probe at z = 0);
//! time of validity `t_valid` in seconds of simulation/acquisition time.

pub mod cdr;
pub mod ros;
pub mod types;
pub mod viz;
pub mod wire;

pub use types::{MessageType, WireMessage};
pub use wire::*;
