//! Lending: memory a decoding may share rather than copy ([`lend`], [`lend_whole`]),
//! found again by the bytes decoded from it ([`lent_slice`]).

use std::cell::RefCell;
use std::sync::Arc;

/// Memory lent on this thread ([`lend`], [`lend_whole`]).
struct Lending {
    memory: ::bytes::Bytes,
    /// Only bytes that are this memory exactly, whole, share it.
    whole_only: bool,
}

impl Lending {
    /// Whether bytes at `part` share this memory.
    fn holds(&self, part: &[u8]) -> bool {
        let (start, end) = (
            self.memory.as_ptr() as usize,
            self.memory.as_ptr() as usize + self.memory.len(),
        );
        let (from, to) = (part.as_ptr() as usize, part.as_ptr() as usize + part.len());
        if self.whole_only {
            !part.is_empty() && start == from && to == end
        } else {
            !part.is_empty() && start <= from && to <= end
        }
    }
}

thread_local! {
    /// The memory lent on this thread, innermost last.
    static LENT: RefCell<Vec<Lending>> = const { RefCell::new(Vec::new()) };
}

/// Takes `count` lendings off this thread's stack when dropped (even in a panic).
struct Return(usize);

impl Drop for Return {
    fn drop(&mut self) {
        LENT.with(|lent| {
            let mut lent = lent.borrow_mut();
            let keep = lent.len().saturating_sub(self.0);
            lent.truncate(keep);
        });
    }
}

/// Calls `read` with `owner`'s bytes, lent: a [`Bytes`](super::Bytes) decoded from them meanwhile
/// on this thread shares `owner` (kept alive by it) instead of copying.
pub fn lend<O, R>(owner: O, read: impl FnOnce(&[u8]) -> R) -> R
where
    O: AsRef<[u8]> + Send + 'static,
{
    let memory = ::bytes::Bytes::from_owner(owner);
    LENT.with(|lent| {
        lent.borrow_mut().push(Lending {
            memory: memory.clone(),
            whole_only: false,
        });
    });
    let _return = Return(1);
    read(&memory)
}

/// Calls `read` with the bytes of `parts`, the parts of one message in order, each
/// with whether it may be shared: a [`Bytes`](super::Bytes) decoded meanwhile on this thread whose
/// bytes are exactly such a part (that memory, all of it) shares that part's owner
/// instead of copying. A message sent with a loaned buffer in it ([`Bytes::loan`](super::Bytes::loan))
/// arrives as such parts, the loaned buffer one of them. Returns what `read`
/// returned, and how many parts it still shares (its `Bytes` keep them alive).
pub fn lend_whole<O, R>(parts: Vec<(O, bool)>, read: impl FnOnce(&[&[u8]]) -> R) -> (R, usize)
where
    O: AsRef<[u8]> + Send + 'static,
{
    /// A part's owner, and a count of who holds it.
    struct Held<O> {
        owner: O,
        _held: Arc<()>,
    }
    impl<O: AsRef<[u8]>> AsRef<[u8]> for Held<O> {
        fn as_ref(&self) -> &[u8] {
            self.owner.as_ref()
        }
    }
    let mut held = Vec::new();
    let mut memory = Vec::with_capacity(parts.len());
    let mut lent = 0;
    LENT.with(|lendings| {
        let mut lendings = lendings.borrow_mut();
        for (owner, shared) in parts {
            let count = Arc::new(());
            let bytes = ::bytes::Bytes::from_owner(Held {
                owner,
                _held: Arc::clone(&count),
            });
            if shared {
                lendings.push(Lending {
                    memory: bytes.clone(),
                    whole_only: true,
                });
                lent += 1;
                held.push(count);
            }
            memory.push(bytes);
        }
    });
    let value = {
        let _return = Return(lent);
        let slices: Vec<&[u8]> = memory.iter().map(|part| &part[..]).collect();
        read(&slices)
    };
    drop(memory);
    let shared = held
        .iter()
        .filter(|count| Arc::strong_count(count) > 1)
        .count();
    (value, shared)
}

/// The lent memory holding `part`, sliced to it, if any.
pub(super) fn lent_slice(part: &[u8]) -> Option<::bytes::Bytes> {
    LENT.with(|lent| {
        lent.borrow()
            .iter()
            .rev()
            .find(|lending| lending.holds(part))
            .map(|lending| lending.memory.slice_ref(part))
    })
}
