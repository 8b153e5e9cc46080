//! One way to take a mutex in this crate: whatever a holder that panicked left.
//!
//! Every lock here guards state its holders keep consistent at each step (counters,
//! tables, a path's parts); a panic in a callback run under one (a user's converter,
//! a delivery) must not make the bridge, ledger or node unusable for the threads
//! that go on. So a poisoned mutex is taken as it is.

use std::sync::{Mutex, MutexGuard, PoisonError};

/// The guard of `mutex`, poisoned or not.
pub(crate) fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}
