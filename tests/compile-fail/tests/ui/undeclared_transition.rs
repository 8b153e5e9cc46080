//! `open` may go to `closed` only: choosing `jammed` does not compile.

use coolbot_compile_fail::generated::gate::{Cx, OpenMay};

fn open_choose(cx: &mut Cx<'_>) -> Option<OpenMay> {
    let _ = cx;
    Some(OpenMay::Jammed)
}

fn main() {
    let _ = open_choose;
}
