//! The set of message types and the trait tying a type to its header and element types.

use crate::ros::{RosField, RosMsg};
use crate::wire::*;
use bytemuck::Pod;

/// What a wire type needs to travel over the transport: iceoryx2's `ZeroCopySend` with the
/// `ipc` feature, nothing without it (then the types are plain data for files and analysis).
#[cfg(feature = "ipc")]
pub trait Transportable: iceoryx2::prelude::ZeroCopySend {}
#[cfg(feature = "ipc")]
impl<T: iceoryx2::prelude::ZeroCopySend> Transportable for T {}
/// What a wire type needs to travel over the transport (nothing without the `ipc` feature).
#[cfg(not(feature = "ipc"))]
pub trait Transportable {}
#[cfg(not(feature = "ipc"))]
impl<T> Transportable for T {}
use std::fmt::Debug;

/// Every topic kind of the graph. The string form (`"RfFrameV3"`) is what launch files use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum MessageType {
    ParticleSnapshotV1,
    RfFrameV3,
    IqFrameV3,
    DopplerMapV2,
    VectorFieldV2,
    StageStatsV1,
    FlowStatsV1,
}

impl MessageType {
    /// All message types.
    pub const ALL: [MessageType; 7] = [
        MessageType::ParticleSnapshotV1,
        MessageType::RfFrameV3,
        MessageType::IqFrameV3,
        MessageType::DopplerMapV2,
        MessageType::VectorFieldV2,
        MessageType::StageStatsV1,
        MessageType::FlowStatsV1,
    ];

    /// Name used in launch files and MCAP channel metadata.
    pub fn name(self) -> &'static str {
        match self {
            MessageType::ParticleSnapshotV1 => "ParticleSnapshotV1",
            MessageType::RfFrameV3 => "RfFrameV3",
            MessageType::IqFrameV3 => "IqFrameV3",
            MessageType::DopplerMapV2 => "DopplerMapV2",
            MessageType::VectorFieldV2 => "VectorFieldV2",
            MessageType::StageStatsV1 => "StageStatsV1",
            MessageType::FlowStatsV1 => "FlowStatsV1",
        }
    }

    /// Parses a launch-file name.
    pub fn from_name(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == s)
    }

    /// Parses a name, with an error that names the retired wire versions (launch files and
    /// recordings of an older sonoflow) and what replaced them.
    pub fn parse(s: &str) -> Result<Self, String> {
        if let Some(k) = Self::from_name(s) {
            return Ok(k);
        }
        match RETIRED.iter().find(|r| r.0 == s) {
            Some((old, new, why)) => Err(format!(
                "message type {old} is a retired wire version: this sonoflow reads and writes {new} ({why}); \
                 re-record with this version, or replay with the sonoflow that wrote it"
            )),
            None => Err(format!(
                "unknown message type `{s}`; known: {}",
                Self::ALL.iter().map(|k| k.name()).collect::<Vec<_>>().join(", ")
            )),
        }
    }

    /// The message type whose MCAP schema name is `schema` (`sonoflow_msgs/msg/<name>`), or the
    /// error of [`MessageType::parse`] (retired versions named).
    pub fn from_schema_name(schema: &str) -> Result<Self, String> {
        Self::parse(schema.strip_prefix("sonoflow_msgs/msg/").unwrap_or(schema))
    }

    /// Size of one payload element in bytes.
    pub fn elem_size(self) -> usize {
        crate::with_type!(self, M => std::mem::size_of::<<M as WireMessage>::Elem>())
    }

    /// Size of the header in bytes.
    pub fn header_size(self) -> usize {
        crate::with_type!(self, M => std::mem::size_of::<<M as WireMessage>::Header>())
    }

    /// MCAP schema name of the raw record.
    pub fn schema_name(self) -> String {
        format!("sonoflow_msgs/msg/{}", self.name())
    }

    /// `ros2msg` schema text of the raw record.
    pub fn schema_text(self) -> String {
        crate::with_type!(self, M => crate::ros::schema_text::<<M as WireMessage>::Header, <M as WireMessage>::Elem>())
    }
}

impl std::fmt::Display for MessageType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Wire versions this sonoflow no longer reads: (old name, replacement, what changed).
pub const RETIRED: &[(&str, &str, &str)] = &[
    ("RfFrameV1", "RfFrameV3", "the header gained the element width and the radius of a convex array"),
    ("RfFrameV2", "RfFrameV3", "the header gained the radius of a convex array"),
    (
        "IqFrameV1",
        "IqFrameV3",
        "the header gained the receive aperture: pitch, width, f-number, n_elements, apodisation, radius",
    ),
    ("IqFrameV2", "IqFrameV3", "the receive aperture gained the radius of a convex array"),
    (
        "DopplerMapV1",
        "DopplerMapV2",
        "the header gained the clutter filter: kind, order or rank, cut-off, energy removed",
    ),
    (
        "VectorFieldV1",
        "VectorFieldV2",
        "the header gained the clutter filter of the looks and the looks used and left out",
    ),
];

/// Ties a [`MessageType`] to its header and payload element types.
pub trait WireMessage: 'static {
    const TYPE: MessageType;
    type Header: Pod + Transportable + Debug + Default + RosMsg + RosField + Send;
    type Elem: Pod + Transportable + Debug + Default + RosField + Send;

    /// The common header (first 64 bytes of every header).
    fn common(h: &Self::Header) -> &MsgHeaderV1 {
        bytemuck::from_bytes(&bytemuck::bytes_of(h)[..std::mem::size_of::<MsgHeaderV1>()])
    }
    /// Mutable common header.
    fn common_mut(h: &mut Self::Header) -> &mut MsgHeaderV1 {
        bytemuck::from_bytes_mut(&mut bytemuck::bytes_of_mut(h)[..std::mem::size_of::<MsgHeaderV1>()])
    }
    /// Number of payload elements the header's dimensions imply (None = free length).
    fn expected_len(h: &Self::Header) -> Option<usize>;
}

macro_rules! message_type {
    ($marker:ident, $kind:ident, $h:ty, $e:ty, |$hv:ident| $len:expr) => {
        #[doc = concat!("Marker type of [`MessageType::", stringify!($kind), "`].")]
        pub struct $marker;
        impl WireMessage for $marker {
            const TYPE: MessageType = MessageType::$kind;
            type Header = $h;
            type Elem = $e;
            fn expected_len($hv: &$h) -> Option<usize> {
                $len
            }
        }
    };
}

message_type!(ParticleSnapshot, ParticleSnapshotV1, ParticleSnapshotHeaderV1, ParticleV1, |h| Some(
    h.n_particles as usize
));
message_type!(RfFrame, RfFrameV3, RfFrameHeaderV3, f32, |h| {
    let per = if h.sample_format == SAMPLE_IQ_F32 { 2 } else { 1 };
    Some(h.n_channels as usize * h.n_samples as usize * per)
});
message_type!(IqFrame, IqFrameV3, IqFrameHeaderV3, Complex32, |h| Some(h.grid.nx as usize * h.grid.nz as usize));
message_type!(DopplerMap, DopplerMapV2, DopplerMapHeaderV2, f32, |h| Some(
    h.grid.nx as usize * h.grid.nz as usize * h.n_planes as usize
));
message_type!(VectorField, VectorFieldV2, VectorFieldHeaderV2, f32, |h| Some(
    h.grid.nx as usize * h.grid.nz as usize * h.n_planes as usize
));
message_type!(StageStats, StageStatsV1, StageStatsHeaderV1, u8, |_h| None);
message_type!(FlowStats, FlowStatsV1, FlowStatsHeaderV1, BoundaryFluxV1, |h| Some(h.n_boundaries as usize));

/// Runs `$body` with `$M` bound to the marker type of `$kind` (monomorphised dispatch).
#[macro_export]
macro_rules! with_type {
    ($kind:expr, $M:ident => $body:expr) => {
        match $kind {
            $crate::MessageType::ParticleSnapshotV1 => {
                type $M = $crate::types::ParticleSnapshot;
                $body
            }
            $crate::MessageType::RfFrameV3 => {
                type $M = $crate::types::RfFrame;
                $body
            }
            $crate::MessageType::IqFrameV3 => {
                type $M = $crate::types::IqFrame;
                $body
            }
            $crate::MessageType::DopplerMapV2 => {
                type $M = $crate::types::DopplerMap;
                $body
            }
            $crate::MessageType::VectorFieldV2 => {
                type $M = $crate::types::VectorField;
                $body
            }
            $crate::MessageType::StageStatsV1 => {
                type $M = $crate::types::StageStats;
                $body
            }
            $crate::MessageType::FlowStatsV1 => {
                type $M = $crate::types::FlowStats;
                $body
            }
        }
    };
}
pub use with_type;

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// Names of the current types parse; a retired wire version is refused with a message that
    /// names it and its replacement (what `replay` and the launcher report); others list the
    /// known names.
    #[test]
    fn retired_wire_versions_are_named_in_the_error() {
        for k in MessageType::ALL {
            assert_eq!(MessageType::parse(k.name()), Ok(k));
            assert_eq!(MessageType::from_schema_name(&k.schema_name()), Ok(k));
        }
        let e = MessageType::from_schema_name("sonoflow_msgs/msg/IqFrameV1").unwrap_err();
        assert!(e.contains("IqFrameV1") && e.contains("retired") && e.contains("IqFrameV3"), "{e}");
        let e = MessageType::parse("RfFrameV1").unwrap_err();
        assert!(e.contains("RfFrameV3") && e.contains("element width"), "{e}");
        for old in ["RfFrameV2", "IqFrameV2"] {
            let e = MessageType::parse(old).unwrap_err();
            assert!(e.contains(old) && e.contains("retired") && e.contains("radius of a convex array"), "{e}");
        }
        let e = MessageType::parse("VectorFieldV1").unwrap_err();
        assert!(e.contains("VectorFieldV2") && e.contains("clutter filter"), "{e}");
        let e = MessageType::parse("IqFrame").unwrap_err();
        assert!(e.contains("unknown") && e.contains("DopplerMapV2"), "{e}");
    }
}
