//! Where the `rust` blocks of the docs are, and the table of the API fragments: one
//! file, a module by path of both `build.rs` here (which compiles each fragment in a
//! function of this package) and `tests/tests/docs.rs` (which counts the fragments
//! among the blocks a test compiles, and checks the ones this package compiled).

use std::path::{Path, PathBuf};

/// The repository root: the nearest directory above the including package's manifest
/// that holds `Cargo.lock` (the workspace's).
pub fn repository() -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"))
        .canonicalize()
        .unwrap();
    manifest
        .ancestors()
        .find(|dir| dir.join("Cargo.lock").is_file())
        .unwrap_or_else(|| panic!("no Cargo.lock above {}", manifest.display()))
        .to_owned()
}

/// The text of the file `name` (from the repository's root).
pub fn doc(name: &str) -> String {
    let path = repository().join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A fenced block of a Markdown file.
pub struct Fence {
    /// Its info string (`rust`, `cool`, `sh`, empty).
    pub info: String,
    /// The heading it stands under: the nearest one above it, the whole line.
    pub heading: String,
    /// The line its opening fence is on (1-based).
    pub line: usize,
    pub body: String,
}

/// The fenced blocks of `text`, in order, with the heading each stands under (a
/// line starting with `#` inside a block is not a heading).
pub fn fences(text: &str) -> Vec<Fence> {
    let mut found = Vec::new();
    let mut heading = String::new();
    let mut open: Option<Fence> = None;
    for (index, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        match &mut open {
            None if trimmed.starts_with("```") => {
                open = Some(Fence {
                    info: trimmed.trim_start_matches('`').trim().to_owned(),
                    heading: heading.clone(),
                    line: index + 1,
                    body: String::new(),
                });
            }
            None if line.starts_with('#') => heading = line.to_owned(),
            None => {}
            Some(_) if trimmed.starts_with("```") => found.extend(open.take()),
            Some(fence) => {
                fence.body.push_str(line);
                fence.body.push('\n');
            }
        }
    }
    found
}

/// A `rust` block of the docs: the file (from the repository's root), the heading it
/// stands under, and its index among the `rust` blocks under that heading.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct Place {
    pub doc: &'static str,
    pub heading: &'static str,
    pub index: usize,
}

pub const fn place(doc: &'static str, heading: &'static str, index: usize) -> Place {
    Place {
        doc,
        heading,
        index,
    }
}

impl Place {
    /// The block.
    pub fn fence(&self) -> Fence {
        fences(&doc(self.doc))
            .into_iter()
            .filter(|fence| fence.info == "rust" && fence.heading == self.heading)
            .nth(self.index)
            .unwrap_or_else(|| panic!("no rust block at {self:?}"))
    }

    /// The block's text.
    #[allow(dead_code)] // (the build script reads the whole fence)
    pub fn text(&self) -> String {
        self.fence().body
    }
}

/// The API fragments of the docs (statements that use what their page describes), each
/// with what its function declares before it; the package's description
/// (`cool/fragments.cool`) and `src/fragments.rs` declare the rest.
pub const FRAGMENTS: &[(Place, &str)] = &[
    (place("docs/runtime.md", "## Components and systems", 0), ""),
    (
        place("docs/runtime.md", "## The monitoring port `m`", 0),
        "let mut system = System::new();\nlet parts = RobotParts::default();\n",
    ),
    (
        place(
            "docs/runtime.md",
            "### The clock: real, or virtual for tests (`coolbot::clock`)",
            0,
        ),
        "",
    ),
    (place("docs/runtime.md", "#### Taking time", 0), ""),
    (
        place(
            "docs/runtime.md",
            "## Compound components and supervisors (paper 3.4, 3.5)",
            0,
        ),
        "let mut system = System::new();\n",
    ),
    (
        place("docs/runtime.md", "### Configuration and defaults", 0),
        "",
    ),
    (place("docs/runtime.md", "## Errors", 0), ""),
    (place("docs/runtime.md", "## Errors", 1), ""),
    (
        place(
            "docs/tools.md",
            "## Recording port traffic: `coolbot::record`",
            0,
        ),
        "let system = System::new();\nlet other_system = System::new();\n",
    ),
    (
        place("docs/tools.md", "### rosbag2 bags: `RecordFormat::Ros2`", 0),
        "let system = System::new();\n",
    ),
    (
        place("docs/distribution.md", "## The model", 0),
        "let mut system = System::new();\n",
    ),
    (
        place("docs/ros2.md", "## Topics on the rmw_zenoh wire", 0),
        "type Twist = crate::generated::types::RosTwist;\nlet mut system = System::new();\n",
    ),
    (
        place("docs/distribution.md", "## Same host: shared memory", 0),
        "use crate::generated::types::Image;\n\
         struct Camera;\n\
         impl Camera { fn read_frame_into(&mut self, frame: &mut [u8]) { frame.fill(1); } }\n\
         let mut camera = Camera;\n\
         struct Outputs { image: coolbot::port::DataOut<Image> }\n\
         let outputs = Outputs { image: coolbot::port::DataOut::new() };\n",
    ),
    (
        place("docs/distribution.md", "### What is built: the agent", 0),
        "let config = coolbot_zenoh::zenoh::Config::default();\n\
         let robot_node = Node::open(\"robot\", coolbot_zenoh::zenoh::Config::default())?;\n",
    ),
];
