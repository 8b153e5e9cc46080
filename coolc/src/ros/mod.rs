//! ROS 2 interface definitions: `.msg` files read into a model, with their type
//! descriptions and RIHS01 hashes (REP-2016) and DDS type names, so that a ROS 2
//! message type can be a packet type (`docs/ros2.md`).
//!
//! One idea per module, data flowing one way:
//! - `names`: the naming rules, and [`TypeName`] (`sensor_msgs/msg/LaserScan`);
//! - `msg`: the model of one file ([`Message`]: fields, constants, defaults, spans);
//! - `parse`: one file's text to a [`Message`] and its diagnostics;
//! - `lookup`: where a type's file is found ([`Search`]: explicit directories,
//!   `AMENT_PREFIX_PATH`, the shipped set);
//! - `shipped`: the `.msg` files compiled into coolc;
//! - `load`: a set of types and every type they reference ([`Interfaces`]);
//! - `description`: the type description of a type ([`TypeDescription`]);
//! - `hash`: its RIHS01 hash ([`TypeHash`]);
//! - `definition`: its full message definition as a rosbag2 bag holds it.
//!
//! ```
//! use std::path::Path;
//!
//! use coolc::ast::Span;
//! use coolc::ros::{Search, TypeName, Wanted, load};
//!
//! // A type is asked for somewhere: a missing type is reported there.
//! let mut sources = coolc::SourceMap::new();
//! let asked = "sensor_msgs/msg/LaserScan";
//! let file = sources.add("main.cool", asked);
//! let wanted = [Wanted { name: asked, file, span: Span::new(0, asked.len()) }];
//!
//! // Explicit directories, then AMENT_PREFIX_PATH, then the shipped set.
//! let search = Search::from_env([Path::new("my_interfaces").to_path_buf()]);
//! let read = |path: &Path| std::fs::read_to_string(path);
//! let interfaces = load(&search, &wanted, &mut sources, &read);
//! let options = coolc::RenderOptions::plain();
//! let rendered = coolc::diagnostics::render(&sources, &interfaces.diagnostics, options);
//! assert!(!interfaces.has_errors(), "{rendered}");
//!
//! let scan = TypeName::parse(asked).unwrap();
//! assert_eq!(scan.dds_name(), "sensor_msgs::msg::dds_::LaserScan_");
//! assert_eq!(
//!     interfaces.hash(&scan).unwrap().to_string(),
//!     "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828"
//! );
//! ```

pub(crate) mod definition;
pub mod description;
pub mod hash;
pub mod load;
pub(crate) mod lookup;
pub mod msg;
pub(crate) mod names;
pub mod parse;
pub mod shipped;

pub use description::TypeDescription;
pub use hash::TypeHash;
pub use load::{Interfaces, Wanted, load};
pub use lookup::Search;
pub use msg::Message;
pub use names::TypeName;
