//! `coolbot`: the CoolBOT runtime. Components are port automata on their own threads.
#![deny(missing_docs)]
