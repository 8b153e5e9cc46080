//! Why a compound could not be built ([`CompoundError`]), and why a running compound
//! fails (its faults, turned into the compound's `error` with their sources).

/// Why a compound could not be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CompoundError {
    /// The supervisor's spec is inconsistent.
    #[error("compound `{compound}`: supervisor: {detail}")]
    Supervisor {
        /// The compound.
        compound: String,
        /// What is wrong.
        detail: String,
    },
    /// An instance could not be added (duplicate name, bad spec, ports).
    #[error("compound `{compound}`: {detail}")]
    Instance {
        /// The compound.
        compound: String,
        /// The system's error.
        detail: String,
    },
    /// A name that does not resolve.
    #[error("compound `{compound}`: {what} `{name}` does not exist")]
    Unknown {
        /// The compound.
        compound: String,
        /// What kind of thing (`instance`, `state`, `variable`, ...).
        what: &'static str,
        /// The name.
        name: String,
    },
    /// A connection breaks the connection rules.
    #[error("compound `{compound}`: {detail}")]
    Connect {
        /// The compound.
        compound: String,
        /// The connection error.
        detail: String,
    },
    /// A substitution or redundancy whose members differ in interface, or that
    /// overlaps another.
    #[error("compound `{compound}`: {detail}")]
    Arrangement {
        /// The compound.
        compound: String,
        /// What is wrong.
        detail: String,
    },
}
