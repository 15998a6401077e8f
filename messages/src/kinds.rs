//! The set of message kinds and the trait tying a kind to its header and element types.

use crate::ros::{RosField, RosMsg};
use crate::wire::*;
use bytemuck::Pod;
use iceoryx2::prelude::ZeroCopySend;
use std::fmt::Debug;

/// Every topic kind of the graph. The string form (`"RfFrameV1"`) is what launch files use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum MessageKind {
    ParticleSnapshotV1,
    RfFrameV1,
    IqFrameV1,
    DopplerMapV1,
    VectorFieldV1,
    StageStatsV1,
    FlowStatsV1,
}

impl MessageKind {
    /// All kinds.
    pub const ALL: [MessageKind; 7] = [
        MessageKind::ParticleSnapshotV1,
        MessageKind::RfFrameV1,
        MessageKind::IqFrameV1,
        MessageKind::DopplerMapV1,
        MessageKind::VectorFieldV1,
        MessageKind::StageStatsV1,
        MessageKind::FlowStatsV1,
    ];

    /// Name used in launch files and MCAP channel metadata.
    pub fn name(self) -> &'static str {
        match self {
            MessageKind::ParticleSnapshotV1 => "ParticleSnapshotV1",
            MessageKind::RfFrameV1 => "RfFrameV1",
            MessageKind::IqFrameV1 => "IqFrameV1",
            MessageKind::DopplerMapV1 => "DopplerMapV1",
            MessageKind::VectorFieldV1 => "VectorFieldV1",
            MessageKind::StageStatsV1 => "StageStatsV1",
            MessageKind::FlowStatsV1 => "FlowStatsV1",
        }
    }

    /// Parses a launch-file name.
    pub fn from_name(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == s)
    }

    /// Size of one payload element in bytes.
    pub fn elem_size(self) -> usize {
        crate::with_kind!(self, M => std::mem::size_of::<<M as WireMessage>::Elem>())
    }

    /// Size of the header in bytes.
    pub fn header_size(self) -> usize {
        crate::with_kind!(self, M => std::mem::size_of::<<M as WireMessage>::Header>())
    }

    /// MCAP schema name of the raw record.
    pub fn schema_name(self) -> String {
        format!("sonoflow_msgs/msg/{}", self.name())
    }

    /// `ros2msg` schema text of the raw record.
    pub fn schema_text(self) -> String {
        crate::with_kind!(self, M => crate::ros::schema_text::<<M as WireMessage>::Header, <M as WireMessage>::Elem>())
    }
}

impl std::fmt::Display for MessageKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Ties a [`MessageKind`] to its header and payload element types.
pub trait WireMessage: 'static {
    const KIND: MessageKind;
    type Header: Pod + ZeroCopySend + Debug + Default + RosMsg + RosField + Send;
    type Elem: Pod + ZeroCopySend + Debug + Default + RosField + Send;

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

macro_rules! kind {
    ($marker:ident, $kind:ident, $h:ty, $e:ty, |$hv:ident| $len:expr) => {
        #[doc = concat!("Marker type of [`MessageKind::", stringify!($kind), "`].")]
        pub struct $marker;
        impl WireMessage for $marker {
            const KIND: MessageKind = MessageKind::$kind;
            type Header = $h;
            type Elem = $e;
            fn expected_len($hv: &$h) -> Option<usize> {
                $len
            }
        }
    };
}

kind!(ParticleSnapshot, ParticleSnapshotV1, ParticleSnapshotHeaderV1, ParticleV1, |h| Some(h.n_particles as usize));
kind!(RfFrame, RfFrameV1, RfFrameHeaderV1, f32, |h| {
    let per = if h.sample_format == SAMPLE_IQ_F32 { 2 } else { 1 };
    Some(h.n_channels as usize * h.n_samples as usize * per)
});
kind!(IqFrame, IqFrameV1, IqFrameHeaderV1, Complex32, |h| Some(h.grid.nx as usize * h.grid.nz as usize));
kind!(DopplerMap, DopplerMapV1, DopplerMapHeaderV1, f32, |h| Some(
    h.grid.nx as usize * h.grid.nz as usize * h.n_planes as usize
));
kind!(VectorField, VectorFieldV1, VectorFieldHeaderV1, f32, |h| Some(
    h.grid.nx as usize * h.grid.nz as usize * h.n_planes as usize
));
kind!(StageStats, StageStatsV1, StageStatsHeaderV1, u8, |_h| None);
kind!(FlowStats, FlowStatsV1, FlowStatsHeaderV1, BoundaryFluxV1, |h| Some(h.n_boundaries as usize));

/// Runs `$body` with `$M` bound to the marker type of `$kind` (monomorphised dispatch).
#[macro_export]
macro_rules! with_kind {
    ($kind:expr, $M:ident => $body:expr) => {
        match $kind {
            $crate::MessageKind::ParticleSnapshotV1 => {
                type $M = $crate::kinds::ParticleSnapshot;
                $body
            }
            $crate::MessageKind::RfFrameV1 => {
                type $M = $crate::kinds::RfFrame;
                $body
            }
            $crate::MessageKind::IqFrameV1 => {
                type $M = $crate::kinds::IqFrame;
                $body
            }
            $crate::MessageKind::DopplerMapV1 => {
                type $M = $crate::kinds::DopplerMap;
                $body
            }
            $crate::MessageKind::VectorFieldV1 => {
                type $M = $crate::kinds::VectorField;
                $body
            }
            $crate::MessageKind::StageStatsV1 => {
                type $M = $crate::kinds::StageStats;
                $body
            }
            $crate::MessageKind::FlowStatsV1 => {
                type $M = $crate::kinds::FlowStats;
                $body
            }
        }
    };
}
pub use with_kind;
