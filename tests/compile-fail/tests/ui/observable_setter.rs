//! `openings` is an observable variable of the gate: its handle has no setter, and the
//! compiler says why rather than "no method named `set_openings`".

use coolbot_compile_fail::generated::door::{Cx, Supervisor};

struct Door;

impl Supervisor for Door {
    fn watching_entry(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.instances.gate().set_openings(3u32)?;
        Ok(())
    }
}

fn main() {
    let _ = Door;
}
