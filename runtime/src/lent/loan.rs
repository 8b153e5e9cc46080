//! Loans: where [`Bytes::loan`](super::Bytes::loan) takes its buffers (the process's
//! [`Lender`], a stack of them: a node with shared memory pushes its pool), and how an
//! encoder finds a loaned buffer in what it serializes ([`encoding_loans`],
//! [`loan_at`]), to send it as the buffer it already is rather than copy it.

use std::any::Any;
use std::cell::{Cell, RefCell};
use std::sync::{Arc, PoisonError, RwLock};

/// A buffer a [`Lender`] lends, while its holder writes it.
pub trait Loan: Send + 'static {
    /// Its bytes.
    fn as_slice(&self) -> &[u8];
    /// Its bytes, to write.
    fn as_mut_slice(&mut self) -> &mut [u8];
    /// Written: read-only and shared from now on.
    fn freeze(self: Box<Self>) -> Arc<dyn Lent>;
}

/// A loaned buffer once written ([`Loan::freeze`]): its bytes, and, as `Any`, what
/// its lender's encoder recognizes it by ([`loan_at`]).
pub trait Lent: AsRef<[u8]> + Any + Send + Sync {}

/// Where [`Bytes::loan`](super::Bytes::loan) takes its buffers from (set with [`push_lender`]).
pub trait Lender: Send + Sync + 'static {
    /// A buffer of exactly `len` bytes, or None (no room: the loan is made on the
    /// heap).
    fn loan(&self, len: usize) -> Option<Box<dyn Loan>>;
}

/// The lenders set, the process's lender last.
static LENDERS: RwLock<Vec<Arc<dyn Lender>>> = RwLock::new(Vec::new());

/// Makes `lender` the process's lender for [`Bytes::loan`](super::Bytes::loan), until it is withdrawn
/// ([`withdraw_lender`]); the lender it follows lends again then.
pub fn push_lender(lender: Arc<dyn Lender>) {
    LENDERS
        .write()
        .unwrap_or_else(PoisonError::into_inner)
        .push(lender);
}

/// `lender` no longer lends: the latest lender set before it and not withdrawn is the
/// process's lender again (none: loans come from the heap).
pub fn withdraw_lender(lender: &dyn Lender) {
    LENDERS
        .write()
        .unwrap_or_else(PoisonError::into_inner)
        .retain(|set| !std::ptr::addr_eq(Arc::as_ptr(set), lender));
}

/// The process's lender, if one is set.
pub fn lender() -> Option<Arc<dyn Lender>> {
    LENDERS
        .read()
        .unwrap_or_else(PoisonError::into_inner)
        .last()
        .cloned()
}

thread_local! {
    /// Encodings under way on this thread that look for loaned buffers
    /// ([`encoding_loans`]).
    static ENCODING: Cell<usize> = const { Cell::new(0) };
    /// The loaned buffers serialized on this thread during those encodings.
    static LOANS: RefCell<Vec<Arc<dyn Lent>>> = const { RefCell::new(Vec::new()) };
}

/// Calls `encode`, during which a loaned [`Bytes`](super::Bytes) serialized on this thread is
/// noted, so that the encoder's writer, handed the bytes, finds their buffer with
/// [`loan_at`] and can send that buffer instead of copying it.
pub fn encoding_loans<R>(encode: impl FnOnce() -> R) -> R {
    ENCODING.with(|depth| depth.set(depth.get() + 1));
    // Undone even if `encode` panics.
    struct Done;
    impl Drop for Done {
        fn drop(&mut self) {
            ENCODING.with(|depth| {
                let left = depth.get().saturating_sub(1);
                depth.set(left);
                if left == 0 {
                    LOANS.with(|loans| loans.borrow_mut().clear());
                }
            });
        }
    }
    let _done = Done;
    encode()
}

/// The loaned buffer that is exactly `bytes` (the same memory, whole), if a
/// [`Bytes`](super::Bytes) serialized in the current [`encoding_loans`] on this thread is one.
pub fn loan_at(bytes: &[u8]) -> Option<Arc<dyn Lent>> {
    if bytes.is_empty() {
        return None;
    }
    LOANS.with(|loans| {
        loans
            .borrow()
            .iter()
            .find(|loan| {
                let whole: &[u8] = (***loan).as_ref();
                std::ptr::eq(whole.as_ptr(), bytes.as_ptr()) && whole.len() == bytes.len()
            })
            .cloned()
    })
}

/// Notes `loan`, a loaned buffer being serialized, for [`loan_at`] when an encoding
/// that looks for loans is under way on this thread ([`encoding_loans`]).
pub(super) fn serialized(loan: &Arc<dyn Lent>) {
    if ENCODING.with(Cell::get) > 0 {
        LOANS.with(|loans| loans.borrow_mut().push(Arc::clone(loan)));
    }
}
