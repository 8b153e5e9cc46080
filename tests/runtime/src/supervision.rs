//! Supervisors for compounds a test builds with `coolbot::CompoundBuilder` around
//! generated components, when the instances need settings no description can give
//! (a negative priority, a nice value; the runtime's adaptation knobs that are Rust
//! only, `docs/language.md`, "`adaptation`").

use crate::generated::coordinating;

/// A supervisor with one state (`supervising`) and no sections: the compound only
/// coordinates its instances (fault policies, adaptation). Its shape is the generated
/// `SPEC` of `Coordinating` (`cool/adapt.cool`).
pub struct Coordinating;

impl coolbot::Supervisor for Coordinating {
    fn spec(&self) -> &'static coolbot::Spec {
        &coordinating::SPEC
    }
}
