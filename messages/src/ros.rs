//! Generation of ROS 2 `.msg` schema text from the wire structs (see [`crate::wire_struct`]).

/// A type that can appear as a field in a ROS 2 message definition.
pub trait RosField {
    /// The field type as written in a `.msg` file (`float32`, `uint8[32]`, `pkg/Type`).
    fn ros_field_type() -> String;
    /// Adds the definitions of nested message types (name, body) this field needs.
    fn collect_deps(_out: &mut Vec<(String, String)>) {}
}

/// A ROS 2 message type generated from a `#[repr(C)]` struct.
pub trait RosMsg {
    /// `pkg/Type`.
    fn ros_type() -> &'static str;
    /// The body of the `.msg` definition (one `type name` line per field).
    fn ros_fields() -> String;
}

macro_rules! prim {
    ($($t:ty => $n:literal),*) => {$(
        impl RosField for $t { fn ros_field_type() -> String { $n.to_string() } }
    )*};
}
prim!(u8 => "uint8", u16 => "uint16", u32 => "uint32", u64 => "uint64", i32 => "int32", i64 => "int64", f32 => "float32", f64 => "float64");

impl<T: RosField, const N: usize> RosField for [T; N] {
    fn ros_field_type() -> String {
        format!("{}[{}]", T::ros_field_type(), N)
    }
    fn collect_deps(out: &mut Vec<(String, String)>) {
        T::collect_deps(out)
    }
}

/// Full `ros2msg` schema text of a message made of `header` followed by `Elem[] data`, with the
/// definitions of every nested type appended in the MCAP/ROS 2 concatenated format.
pub fn schema_text<H: RosField, E: RosField>() -> String {
    let mut text = format!("{} header\n{}[] data\n", H::ros_field_type(), E::ros_field_type());
    let mut deps = Vec::new();
    H::collect_deps(&mut deps);
    E::collect_deps(&mut deps);
    for (name, body) in deps {
        text.push_str(&"=".repeat(80));
        text.push_str("\nMSG: ");
        text.push_str(&name);
        text.push('\n');
        text.push_str(&body);
    }
    text
}

/// Declares a wire struct: `#[repr(C)]`, `Pod`, iceoryx2 `ZeroCopySend` with a versioned type
/// name, zeroed `Default`, and its ROS 2 message definition.
#[macro_export]
macro_rules! wire_struct {
    ($(#[$m:meta])* pub struct $name:ident as $ros:literal { $( $(#[$fm:meta])* pub $f:ident : $t:ty ),* $(,)? }) => {
        $(#[$m])*
        #[repr(C)]
        #[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
        #[cfg_attr(feature = "ipc", derive(iceoryx2::prelude::ZeroCopySend), type_name($ros))]
        pub struct $name { $( $(#[$fm])* pub $f: $t ),* }
        impl Default for $name {
            fn default() -> Self { bytemuck::Zeroable::zeroed() }
        }
        impl $crate::ros::RosMsg for $name {
            fn ros_type() -> &'static str { $ros }
            fn ros_fields() -> String {
                let mut s = String::new();
                $( s.push_str(&<$t as $crate::ros::RosField>::ros_field_type()); s.push(' '); s.push_str(stringify!($f)); s.push('\n'); )*
                s
            }
        }
        impl $crate::ros::RosField for $name {
            fn ros_field_type() -> String { $ros.to_string() }
            fn collect_deps(out: &mut Vec<(String, String)>) {
                $( <$t as $crate::ros::RosField>::collect_deps(out); )*
                if !out.iter().any(|(n, _)| n == $ros) {
                    out.push(($ros.to_string(), <$name as $crate::ros::RosMsg>::ros_fields()));
                }
            }
        }
    };
}
