//! Acknowledgments across a bridge (`docs/distribution.md`, "What happens when the
//! network fails"): what an inlet has had of each outlet, what an outlet counts lost
//! when an inlet's process ends before acknowledging what it was sent, and what an
//! inlet counts missing when an outlet reports that its killed predecessor had sent
//! more than the inlet received.
//!
//! An outlet numbers its messages (1, 2, ... per epoch). An inlet keeps, per outlet
//! epoch, the first and newest number it received, how many it received and how many
//! it counted missing (gaps, at its own `network` input), and answers queries on
//! `K/@ack/<node>/<name>` with that and its process (drawn once per process, also the
//! last chunk of its token `K/@in/<node>/<name>/<process>`). The outlet looks every
//! [`ACK_PERIOD`] and asks when a live inlet is [`ASK_BEHIND`] numbers behind what it
//! was sent, or behind at all after [`ASK_PATIENCE`] without a question or
//! [`ASK_QUIET`] without a send (or when it has killed predecessors to report: below),
//! and watches the inlets' tokens; with every inlet caught up and nothing to report it
//! sleeps until the outlet sends ([`Sent`]) or a token comes or goes. When an inlet's
//! process is known to have ended (its token is gone and an inlet token on the key appears from its node with
//! another process, or, on a key with one input end,
//! another inlet has started receiving, or the outlet stops), the numbers sent after
//! the newest it acknowledged are counted lost at the outlet's input, with an event,
//! up to where its successor's share begins. A link that breaks and comes back keeps
//! the same process: the inlet counts the gap itself, and the outlet nothing. The
//! questions carry the epochs of killed predecessors and their newest numbers
//! (`crate::tally`).
//!
//! Numbers come from the network, where any peer that may publish on a key may write
//! them: an inlet counts missing only within [`WINDOW`] of the newest number of an
//! epoch; a message or a report further away is one reset, counted at the inlet's
//! `resets` input.

use crate::locks::lock;
use coolbot::Chain;
use std::collections::HashSet;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering, fence};
use std::sync::{Arc, Mutex, OnceLock};
use std::thread::{JoinHandle, Thread};
use std::time::{Duration, Instant};

use coolbot::port::ErasedInput;
use serde::{Deserialize, Serialize};

use crate::codec;
use crate::tally::Ended;
use zenoh::Wait;
use zenoh::query::{ConsolidationMode, QueryTarget};
use zenoh::sample::SampleKind;

/// How often an outlet looks whether to ask its inlets what they have had.
pub(crate) const ACK_PERIOD: Duration = Duration::from_millis(100);

/// How many numbers a live inlet may be behind what it was sent before the outlet asks
/// at its next look. A round of questions costs both processes together over half the
/// CPU of a 4 MiB packet through shared memory: a stream of a few packets a period
/// (4 MiB frames at 30 Hz) is asked after 16 of them, not every third; a fast one (a
/// pose a millisecond) at every look.
pub(crate) const ASK_BEHIND: u64 = 16;

/// How long an outlet whose inlets are behind, but fewer than [`ASK_BEHIND`] numbers,
/// waits since its last question before it asks: the longest a steady stream's
/// received packets go unacknowledged (what a killed consumer is counted both ways
/// for).
pub(crate) const ASK_PATIENCE: Duration = Duration::from_secs(1);

/// How long an outlet whose inlets are behind waits after its last send before it
/// asks: a burst that ends is acknowledged at once, not a second later (a consumer
/// stopped after a burst is then not counted for what it had).
pub(crate) const ASK_QUIET: Duration = Duration::from_millis(250);

/// How long one round of questions waits for the inlets' answers.
const ACK_TIMEOUT: Duration = Duration::from_millis(300);

/// Rounds in a row in which every inlet the outlet knows answered a question that
/// reported the killed epochs, after which the report is retired (each inlet has
/// counted it: a report counts once).
const RETIRE_ROUNDS: u32 = 3;

/// How long an outlet reports its killed predecessors' epochs at least: a process
/// just started is still finding its peers (an inlet it cannot reach yet has no
/// token it could see), and messages of the killed epoch may still be on their way.
const RETIRE_AFTER: Duration = Duration::from_secs(10);

/// What an outlet does once its killed predecessors' report is retired: clear it
/// from its tally, so that the next outlet does not report it again.
pub(crate) type Retire = Box<dyn Fn() + Send + Sync>;

/// How many rounds an outlet that stops asks, waiting for its live inlets to
/// acknowledge everything it sent, before counting the rest lost.
const FINAL_ROUNDS: usize = 5;

/// The `tracing` target of every receipt and acknowledgment an inlet records, and of
/// every number an outlet hands to Zenoh (at `trace` level: a test's ground truth).
pub const LEDGER_TARGET: &str = "coolbot_zenoh::ledger";

/// The `tracing` target of what an outlet counts lost for an ended inlet (`trace`:
/// `<key> counted <inlet> from <newest acknowledged> to <end>`).
pub const OUTLET_LEDGER_TARGET: &str = "coolbot_zenoh::ledger::outlet";

/// An outlet's count of the numbered messages it sent, which its ledger's thread
/// reads: that thread sleeps while every inlet has acknowledged everything and there
/// is nothing to report, and the next send (or an inlet's token, [`Sent::nudge`])
/// wakes it. A send costs a fence and one more atomic load; only the first send after
/// such a sleep wakes the thread.
#[derive(Default)]
pub(crate) struct Sent {
    count: AtomicU64,
    /// The ledger's thread sleeps with nothing to ask: the next send wakes it.
    asleep: AtomicBool,
    /// Something to look at came (an inlet's token) since the thread last looked.
    nudged: AtomicBool,
    /// The ledger's thread, once it runs.
    thread: OnceLock<Thread>,
}

impl Sent {
    /// The newest number sent (0: none yet).
    pub(crate) fn get(&self) -> u64 {
        self.count.load(Ordering::Acquire)
    }

    /// Message `number` was sent: wakes the ledger's thread if it sleeps.
    pub(crate) fn set(&self, number: u64) {
        self.count.store(number, Ordering::Release);
        // Paired with the fence in `sleep`: either the thread sees this number before
        // it parks, or this sees it asleep and unparks it.
        fence(Ordering::SeqCst);
        if self.asleep.load(Ordering::Relaxed) {
            self.wake();
        }
    }

    /// Something for the ledger's thread to look at (an inlet's token came or went):
    /// its next sleep does not park before it has looked.
    fn nudge(&self) {
        self.nudged.store(true, Ordering::Release);
        fence(Ordering::SeqCst);
        if self.asleep.load(Ordering::Relaxed) {
            self.wake();
        }
    }

    /// On the ledger's thread, as a look begins: the nudges so far are looked at.
    fn looking(&self) {
        self.nudged.store(false, Ordering::Release);
    }

    /// Wake the ledger's thread if it sleeps.
    fn wake(&self) {
        if self.asleep.swap(false, Ordering::AcqRel)
            && let Some(thread) = self.thread.get()
        {
            thread.unpark();
        }
    }

    /// On the ledger's thread: sleep until [`Sent::set`], [`Sent::nudge`] or a
    /// spurious wake-up, unless a nudge came since the last look or `idle` (asked
    /// after the thread said it sleeps) says there is something to do.
    fn sleep(&self, idle: impl Fn() -> bool) {
        self.thread.get_or_init(std::thread::current);
        self.asleep.store(true, Ordering::Relaxed);
        fence(Ordering::SeqCst);
        if !self.nudged.load(Ordering::Acquire) && idle() {
            std::thread::park();
        }
        self.asleep.store(false, Ordering::Release);
    }
}

/// What an inlet has had of one outlet epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct Had {
    epoch: u64,
    first: u64,
    newest: u64,
    received: u64,
    missing: u64,
}

/// An inlet's answer: its process, and what it has had of each outlet epoch.
type Ack = (String, Vec<Had>);

/// The most outlet epochs an inlet remembers: a key has few producers, and each
/// restart of one is a new epoch. Beyond, the epoch with the fewest messages
/// received is forgotten.
const MAX_EPOCHS: usize = 64;

/// How far from the newest number of its epoch a message's number, or an ended
/// epoch's reported newest number, may be to count what lies between as missing:
/// 2^20 numbers. More than the messages of a few dozen bytes that Zenoh's queues and
/// the TCP buffers between two nodes hold when a link breaks or a process is killed,
/// which is what an honest outlet's numbering can skip; further is a **reset**,
/// counted once (at the inlet's `resets` input, with its event), and nothing is
/// counted missing for it. So a peer that may publish on a key can add at most this
/// many to the inlet's missing count per message it forges, and a number it picks at
/// random adds nothing.
const WINDOW: u64 = 1 << 20;

/// The longest question an inlet decodes: the killed epochs an outlet reports (at
/// most [`crate::tally::KEPT`]), each two `u64`s of at most 10 bytes, after their
/// count.
const MAX_REPORT: usize = crate::tally::KEPT * 20 + 10;

/// The longest acknowledgment an outlet decodes: an inlet's process (a few dozen
/// hexadecimal digits) and [`MAX_EPOCHS`] epochs of five `u64`s.
const MAX_ACK: usize = 256 + MAX_EPOCHS * 50 + 10;

/// One outlet epoch as an inlet knows it: what it has had, and where its numbering
/// jumped out of the [`WINDOW`].
struct Epoch {
    had: Had,
    /// The number of the last message that jumped out of the window: when the next
    /// one follows it (the outlet's numbering really moved), the count goes on from
    /// there; when the next one follows `had.newest` instead, it was a stray.
    jumped: Option<u64>,
    /// The newest number of the last report of this epoch's end that was too far to
    /// count (a reset): the same report again (an outlet repeats it every round) is
    /// not another one.
    reported: Option<u64>,
}

/// An inlet's side: the numbers received per outlet epoch; the numbers skipped
/// between two received are lost, counted at the inlet's `network` input with the
/// reason. The first message of an epoch counts nothing before it (what an outlet
/// sent before the inlet subscribed was counted at the outlet, as sent to nobody). A
/// jump beyond the [`WINDOW`] is a reset, counted at `resets`.
pub(crate) struct InletLedger {
    epochs: Mutex<Vec<Epoch>>,
    network: Arc<ErasedInput>,
    resets: Arc<ErasedInput>,
    key: String,
}

impl InletLedger {
    pub(crate) fn new(
        network: Arc<ErasedInput>,
        resets: Arc<ErasedInput>,
        key: String,
    ) -> InletLedger {
        InletLedger {
            epochs: Mutex::new(Vec::new()),
            network,
            resets,
            key,
        }
    }

    /// Message `seq` of outlet `epoch` arrived (0: a pull answer, not numbered).
    pub(crate) fn received(&self, epoch: u64, seq: u64) {
        if seq == 0 {
            return;
        }
        let (missing, reset) = {
            let mut epochs = lock(&self.epochs);
            let (missing, reset) = match epochs.iter_mut().find(|e| e.had.epoch == epoch) {
                Some(e) => {
                    let h = &mut e.had;
                    h.received = h.received.saturating_add(1);
                    let (missing, reset) = if seq.abs_diff(h.newest) <= WINDOW {
                        // Within the window of the stream (a stray jump before it is
                        // forgotten): the numbers skipped are missing.
                        e.jumped = None;
                        let missing = seq.saturating_sub(h.newest.saturating_add(1));
                        h.newest = h.newest.max(seq);
                        (missing, false)
                    } else {
                        match e.jumped {
                            // It follows the last jump: the numbering moved there.
                            Some(jumped) if seq > jumped && seq - jumped <= WINDOW => {
                                e.jumped = None;
                                h.newest = seq;
                                (seq - jumped - 1, false)
                            }
                            _ => {
                                e.jumped = Some(seq);
                                (0, true)
                            }
                        }
                    };
                    h.missing = h.missing.saturating_add(missing);
                    (missing, reset)
                }
                None => {
                    if epochs.len() >= MAX_EPOCHS {
                        // The epoch with the fewest messages goes (the oldest of
                        // those): a peer that puts one message each of many epochs
                        // it makes up replaces its own, never a stream with a
                        // history, which would then start again from whatever came
                        // next (a reset for the stream's next message, when that
                        // was a forged number).
                        let fewest = epochs
                            .iter()
                            .enumerate()
                            .min_by_key(|(at, e)| (e.had.received, *at))
                            .map_or(0, |(at, _)| at);
                        epochs.remove(fewest);
                    }
                    epochs.push(Epoch {
                        had: Had {
                            epoch,
                            first: seq,
                            newest: seq,
                            received: 1,
                            missing: 0,
                        },
                        jumped: None,
                        reported: None,
                    });
                    (0, false)
                }
            };
            // Under the lock: a test reads receipts and acknowledgments in the order
            // the ledger saw them.
            tracing::trace!(target: LEDGER_TARGET, "{} received {epoch} {seq} missing {missing}", self.key);
            if reset {
                tracing::trace!(target: LEDGER_TARGET, "{} reset {epoch} {seq}", self.key);
            }
            (missing, reset)
        };
        if missing > 0 {
            self.network.count_loss(missing);
            coolbot::limited!(
                &self.key,
                |held| tracing::warn!(key = %self.key, "inlet lost {missing} packet(s) on the way (numbers missing){held}")
            );
        }
        if reset {
            self.resets.count_loss(1);
            coolbot::limited!(&self.key, |held| tracing::warn!(
                key = %self.key,
                "outlet epoch {epoch} jumped to number {seq}, more than {WINDOW} from its stream: a reset, nothing counted missing{held}"
            ));
        }
    }

    /// The answer to an outlet's question, from the inlet of `process`; `ended`, the
    /// outlet epochs the question reports ended (by a process started again, from
    /// its tally) with the newest number each sent. Numbers of an epoch this inlet
    /// had that it never received up to that newest are counted missing, once; a
    /// newest further than the [`WINDOW`] is a reset, counted once. An epoch it never
    /// had counts nothing: every inlet on the key hears the report, and only those
    /// that had the epoch can tell what they missed. How many were counted missing.
    /// The reported numbers come from a file a killed process left, or from any peer
    /// that may ask: any value is taken without overflow.
    fn answer(&self, process: &str, ended: &[Ended]) -> (Vec<u8>, u64) {
        let mut epochs = lock(&self.epochs);
        let mut counted: u64 = 0;
        let mut resets: u64 = 0;
        for &(epoch, last) in ended {
            let Some(e) = epochs.iter_mut().find(|e| e.had.epoch == epoch) else {
                continue;
            };
            let h = &mut e.had;
            if last <= h.newest {
                continue;
            }
            let missing = last - h.newest;
            if missing > WINDOW {
                if e.reported != Some(last) {
                    e.reported = Some(last);
                    resets += 1;
                    tracing::trace!(target: LEDGER_TARGET, "{} reset {epoch} {last}", self.key);
                    coolbot::limited!(&self.key, |held| tracing::warn!(
                        key = %self.key,
                        "outlet epoch {epoch} reported ended at number {last}, more than {WINDOW} after what this inlet received: a reset, nothing counted missing{held}"
                    ));
                }
                continue;
            }
            h.newest = last;
            h.missing = h.missing.saturating_add(missing);
            counted = counted.saturating_add(missing);
            tracing::trace!(target: LEDGER_TARGET, "{} ended {epoch} {last} missing {missing}", self.key);
            coolbot::limited!(&self.key, |held| tracing::warn!(
                key = %self.key,
                "inlet lost {missing} packet(s): outlet epoch {epoch} sent up to {last} before its process ended{held}"
            ));
        }
        if counted > 0 {
            self.network.count_loss(counted);
        }
        self.resets.count_loss(resets);
        for e in epochs.iter() {
            tracing::trace!(target: LEDGER_TARGET, "{} acknowledged {} {}", self.key, e.had.epoch, e.had.newest);
        }
        let had: Vec<Had> = epochs.iter().map(|e| e.had).collect();
        let ack: Ack = (process.to_owned(), had);
        (codec::encode(&ack).unwrap_or_default(), counted)
    }
}

/// The queryable through which an inlet acknowledges: `K/@ack/<node>/<name>`;
/// `asked` runs after each question, told whether its report of ended epochs made
/// the inlet count packets missing.
pub(crate) fn serve(
    node: &crate::Node,
    key: &str,
    name: &str,
    ledger: Arc<InletLedger>,
    asked: impl Fn(bool) + Send + Sync + 'static,
) -> zenoh::Result<zenoh::query::Queryable<()>> {
    let own = format!("{key}/@ack/{}/{name}", node.name());
    let replier = node.replier();
    let session = node.session();
    let process = process();
    tracing::trace!(target: LEDGER_TARGET, "{key} inlet {}/{name} of process {process}", node.name());
    let reply_key = own.clone();
    session
        .declare_queryable(own)
        .callback(move |query| {
            let ended = match query.payload() {
                Some(payload) => match codec::decode_payload::<Vec<Ended>>(payload, MAX_REPORT) {
                    Ok(ended) => ended,
                    Err(error) => {
                        coolbot::limited!(&reply_key, |held| tracing::warn!(key = %reply_key, "a question whose report does not decode was answered without it: {}{held}", Chain(&error)));
                        Vec::new()
                    }
                },
                None => Vec::new(),
            };
            let (answer, lost) = ledger.answer(&process, &ended);
            asked(lost > 0);
            // From the node's replier: a querier that does not read its answer holds
            // that thread, not Zenoh's.
            let reply_key = reply_key.clone();
            replier.send("an acknowledgment", move || {
                if let Err(error) = query.reply(reply_key.clone(), answer).wait() {
                    coolbot::limited!(&reply_key, |held| tracing::warn!(
                        "acknowledgment not sent: {}{held}",
                        Chain(&*error)
                    ));
                }
            });
        })
        .wait()
}

/// The last chunk of an inlet's token: its process, a value drawn once per process
/// (its start time and id; not the Zenoh session id, which a configuration may fix).
pub(crate) fn process() -> String {
    static PROCESS: OnceLock<String> = OnceLock::new();
    PROCESS
        .get_or_init(|| {
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |elapsed| elapsed.as_nanos() as u64);
            format!("{now:x}{:x}", std::process::id())
        })
        .clone()
}

/// The most settled inlets an outlet remembers (so that a settled one whose token
/// comes back is not taken for a new inlet).
const MAX_SETTLED: usize = 1024;

/// The most inlets gone an outlet keeps without knowing that they ended (a link
/// that may come back); beyond, the oldest is counted as ended.
const MAX_GONE: usize = 256;

/// One inlet as an outlet knows it: `<node>/<name>/<process>` from its token.
#[derive(Debug, Clone)]
struct Stream {
    id: String,
    node: String,
    process: String,
    /// What the outlet had sent when it first saw the inlet (its token comes before
    /// its subscription: nothing numbered up to here was sent to it).
    since: u64,
    first: u64,
    newest: u64,
    alive: bool,
    /// What the outlet had sent when the token went.
    gone_at: Option<u64>,
    /// Its node answers from another process: this one has ended.
    ended: bool,
    counted: bool,
}

impl Stream {
    fn new(id: &str, since: u64) -> Option<Stream> {
        let mut chunks = id.rsplitn(3, '/');
        let process = chunks.next()?.to_owned();
        let _name = chunks.next()?;
        let node = chunks.next()?.to_owned();
        Some(Stream {
            id: id.to_owned(),
            node,
            process,
            since,
            first: 0,
            newest: 0,
            alive: true,
            gone_at: None,
            ended: false,
            counted: false,
        })
    }
}

struct Book {
    key: String,
    epoch: u64,
    sent: Arc<Sent>,
    /// One input end (fifo, ufifo): an inlet that starts receiving replaces the one
    /// gone.
    single: bool,
    losses: ErasedInput,
    streams: Mutex<Vec<Stream>>,
    /// The inlets already counted for, by id, oldest first.
    settled: Mutex<std::collections::VecDeque<String>>,
    /// What this outlet's killed predecessors (same node, same key) had sent, from
    /// the tallies they left: reported to the inlets with every question until
    /// retired ([`RETIRE_ROUNDS`]).
    ended: Mutex<Vec<Ended>>,
    /// Rounds in a row every known inlet answered while `ended` was reported (since
    /// the last inlet appeared).
    heard: AtomicU32,
    /// When the outlet started: its report is retired [`RETIRE_AFTER`] after at least.
    started: Instant,
    retire: Option<Retire>,
}

impl Book {
    fn sent(&self) -> u64 {
        self.sent.get()
    }

    /// The stream of token `id`, made if it is new. A process of a node seen means
    /// every gone stream of that node from another process has ended.
    fn seen<'s>(&self, streams: &'s mut Vec<Stream>, id: &str) -> Option<&'s mut Stream> {
        let index = match streams.iter().position(|s| s.id == id) {
            Some(index) => index,
            None => {
                // Inlets gone and not known to have ended stay until the outlet stops
                // (their link may come back): beyond [`MAX_GONE`], the oldest is
                // taken as ended and counted, so that tokens a peer declares and
                // withdraws under made-up names do not pile up.
                let mut gone = streams.iter_mut().filter(|s| !s.alive && !s.ended);
                if let Some(oldest) = gone.next()
                    && gone.count() + 1 >= MAX_GONE
                {
                    oldest.ended = true;
                }
                streams.push(Stream::new(id, self.sent())?);
                // A newcomer must hear the report too: the rounds count again.
                self.heard.store(0, Ordering::Release);
                streams.len() - 1
            }
        };
        let (node, process) = (streams[index].node.clone(), streams[index].process.clone());
        for other in streams.iter_mut() {
            if other.node == node && other.process != process && !other.alive {
                other.ended = true;
            }
        }
        streams.get_mut(index)
    }

    fn token(&self, id: &str, kind: SampleKind) {
        // A settled inlet whose link came back after its successor took over: what
        // it was sent is counted already (two inlets on one queue key: see the docs).
        if lock(&self.settled).iter().any(|settled| settled == id) {
            return;
        }
        let sent = self.sent();
        let mut streams = lock(&self.streams);
        if let Some(stream) = self.seen(&mut streams, id) {
            match kind {
                SampleKind::Put => {
                    stream.alive = true;
                    stream.gone_at = None;
                }
                SampleKind::Delete => {
                    stream.alive = false;
                    stream.gone_at = Some(sent);
                }
            }
        }
        // A token that lingered (until its lease ran out) after its node's next
        // process declared its own: gone now, it has ended too.
        if kind == SampleKind::Delete
            && let Some(index) = streams.iter().position(|s| s.id == id)
        {
            let (node, process) = (streams[index].node.clone(), streams[index].process.clone());
            let succeeded = streams[index + 1..]
                .iter()
                .any(|s| s.node == node && s.process != process);
            if succeeded {
                streams[index].ended = true;
            }
        }
    }

    /// An inlet's answer. Only an inlet whose token was seen counts (a late answer
    /// from a process already settled is not a new inlet).
    fn acknowledged(&self, node_and_name: &str, ack: &Ack) {
        let (process, had) = ack;
        let id = format!("{node_and_name}/{process}");
        let mut streams = lock(&self.streams);
        if let Some(stream) = streams.iter_mut().find(|s| s.id == id && !s.counted)
            && let Some(h) = had.iter().find(|h| h.epoch == self.epoch)
        {
            if stream.first == 0 {
                stream.first = h.first;
            }
            stream.newest = stream.newest.max(h.newest);
        }
    }

    /// Count what the ended inlets were sent and never acknowledged; `stopping`:
    /// every inlet is done (the outlet stops).
    ///
    /// The numbers are shared out along the inlets' succession: an inlet gone owns
    /// those after the newest it acknowledged up to where its successor (the first
    /// inlet seen after it went) begins, the number before the first its successor
    /// acknowledged receiving, or, for a successor that acknowledged nothing, what
    /// the outlet had sent when it saw it (that successor then owns all after).
    fn settle(&self, stopping: bool) {
        let sent = self.sent();
        let mut streams = lock(&self.streams);
        let snapshot = streams.clone();
        for (index, stream) in streams.iter_mut().enumerate().filter(|(_, s)| !s.counted) {
            // Seen after it went, or its node's next process (whose token may have
            // come before this one's lingering token went).
            let successor = stream.gone_at.and_then(|gone| {
                snapshot
                    .iter()
                    .enumerate()
                    .filter(|(at, s)| {
                        s.id != stream.id
                            && (s.since >= gone
                                || (*at > index
                                    && s.node == stream.node
                                    && s.process != stream.process))
                    })
                    .map(|(_, s)| s)
                    .min_by_key(|s| s.since)
            });
            let replaced = self.single && !stream.alive && successor.is_some_and(|s| s.first > 0);
            if !(stopping || stream.ended || replaced) {
                continue;
            }
            let end = match (stream.gone_at, successor) {
                (None, _) => sent,
                (Some(gone), None) => gone,
                (Some(_), Some(next)) if next.first > 0 => next.first - 1,
                (Some(_), Some(next)) if stopping || !next.alive => next.since,
                // Its successor may still say where it began.
                (Some(_), Some(_)) => continue,
            };
            stream.counted = true;
            let from = stream.newest.max(stream.since);
            let lost = end.saturating_sub(from);
            tracing::trace!(target: OUTLET_LEDGER_TARGET, "{} counted {} from {from} to {end}", self.key, stream.id);
            if lost > 0 {
                self.losses.count_loss(lost);
                coolbot::limited!(&self.key, |held| tracing::warn!(
                    key = %self.key,
                    "outlet lost {lost} packet(s): inlet {} ended before acknowledging them{held}",
                    stream.id
                ));
            }
        }
        let mut settled = lock(&self.settled);
        for stream in streams.iter().filter(|s| s.counted) {
            if settled.len() >= MAX_SETTLED {
                settled.pop_front();
            }
            settled.push_back(stream.id.clone());
        }
        streams.retain(|s| !s.counted);
    }

    /// Whether every live inlet has acknowledged everything sent.
    fn caught_up(&self) -> bool {
        let sent = self.sent();
        lock(&self.streams)
            .iter()
            .filter(|s| s.alive && !s.counted)
            .all(|s| s.newest.max(s.since) >= sent)
    }

    /// The sum of the newest numbers acknowledged (grows with every new answer).
    fn acknowledged_total(&self) -> u64 {
        lock(&self.streams)
            .iter()
            .fold(0, |total, s| total.saturating_add(s.newest))
    }

    /// The most numbers a live inlet is behind what the outlet sent (0: caught up).
    fn behind(&self) -> u64 {
        let sent = self.sent();
        lock(&self.streams)
            .iter()
            .filter(|s| s.alive && !s.counted)
            .map(|s| sent.saturating_sub(s.newest.max(s.since)))
            .max()
            .unwrap_or(0)
    }

    /// Whether to ask now, `waited` after the last round of questions and `quiet`
    /// after the last send seen: a report of killed predecessors is out (each round
    /// counts towards retiring it), or a live inlet is [`ASK_BEHIND`] numbers behind,
    /// or behind at all and the last round was [`ASK_PATIENCE`] ago or the outlet has
    /// sent nothing for [`ASK_QUIET`]. An outlet whose inlets have everything, with no
    /// report out, asks nothing until it sends again: an inlet that ends now was sent
    /// nothing it did not acknowledge.
    fn wants_asking(&self, waited: Duration, quiet: Duration) -> bool {
        if !lock(&self.ended).is_empty() {
            return true;
        }
        let behind = self.behind();
        behind >= ASK_BEHIND || (behind > 0 && (waited >= ASK_PATIENCE || quiet >= ASK_QUIET))
    }

    /// Whether the outlet's thread has nothing to look at until the outlet sends or
    /// a token comes or goes: no report out and no live inlet behind.
    fn idle(&self) -> bool {
        lock(&self.ended).is_empty() && self.behind() == 0
    }

    /// Whether there is no one to ask: no inlet to account for, nothing to report.
    fn is_empty(&self) -> bool {
        lock(&self.ended).is_empty() && lock(&self.streams).iter().all(|s| s.counted)
    }

    /// One round of questions to the inlets.
    fn ask(&self, session: &zenoh::Session) {
        let prefix = format!("{}/@ack/", self.key);
        let report = codec::encode(&*lock(&self.ended)).unwrap_or_default();
        let replies = match session
            .get(format!("{}/@ack/**", self.key))
            .payload(report)
            .target(QueryTarget::All)
            .consolidation(ConsolidationMode::None)
            .timeout(ACK_TIMEOUT)
            .wait()
        {
            Ok(replies) => replies,
            Err(error) => {
                coolbot::limited!(
                    &self.key,
                    |held| tracing::warn!(key = %self.key, "acknowledgments not asked: {}{held}", Chain(&*error))
                );
                return;
            }
        };
        let mut answered = HashSet::new();
        while let Ok(reply) = replies.recv() {
            let Ok(sample) = reply.result() else { continue };
            let Some(node_and_name) = sample.key_expr().as_str().strip_prefix(&prefix) else {
                continue;
            };
            match codec::decode_payload::<Ack>(sample.payload(), MAX_ACK) {
                Ok(ack) => {
                    answered.insert(format!("{node_and_name}/{}", ack.0));
                    self.acknowledged(node_and_name, &ack);
                }
                Err(error) => coolbot::limited!(&self.key, |held| tracing::warn!(
                    key = %self.key,
                    "an acknowledgment that does not decode was dropped: {}{held}",
                    Chain(&error)
                )),
            }
        }
        self.after_round(&answered);
    }

    /// A round of questions ended, answered by the inlets `answered` (their ids):
    /// the killed epochs' report is retired once [`RETIRE_ROUNDS`] rounds in a row
    /// (since the last inlet appeared) were answered by every inlet the outlet knows,
    /// all alive (one whose link is broken may still have to count it), and at least
    /// one, and not before [`RETIRE_AFTER`].
    fn after_round(&self, answered: &HashSet<String>) {
        let mut ended = lock(&self.ended);
        if ended.is_empty() {
            return;
        }
        let heard = {
            let streams = lock(&self.streams);
            let mut known = streams.iter().filter(|s| !s.counted).peekable();
            known.peek().is_some() && known.all(|s| s.alive && answered.contains(&s.id))
        };
        if !heard {
            self.heard.store(0, Ordering::Release);
            return;
        }
        if self.started.elapsed() < RETIRE_AFTER {
            return;
        }
        if self.heard.fetch_add(1, Ordering::AcqRel) + 1 < RETIRE_ROUNDS {
            return;
        }
        tracing::trace!(target: OUTLET_LEDGER_TARGET, "{} retired {:?}", self.key, *ended);
        ended.clear();
        if let Some(retire) = &self.retire {
            retire();
        }
    }
}

/// An outlet's side: the inlets it has seen, looked at every [`ACK_PERIOD`] while one
/// is behind or a report is out and asked when [`Book::wants_asking`] (otherwise the
/// thread sleeps until the outlet sends or a token comes or goes: [`Sent`]), on a
/// thread of its own; dropping it settles the accounts.
pub(crate) struct OutletLedger {
    book: Arc<Book>,
    session: zenoh::Session,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    watcher: Option<zenoh::pubsub::Subscriber<()>>,
}

impl OutletLedger {
    /// The ledger of the outlet of `epoch` on `key`, whose numbered messages are
    /// counted by `sent`, counting losses at `losses`; `ended`, what its killed
    /// predecessors had sent (their tallies), and `retire`, what clears it from the
    /// tally once every inlet has heard it.
    pub(crate) fn start(
        session: &zenoh::Session,
        key: &str,
        epoch: u64,
        sent: Arc<Sent>,
        single: bool,
        losses: ErasedInput,
        ended: Vec<Ended>,
        retire: Option<Retire>,
    ) -> Result<OutletLedger, crate::Error> {
        let book = Arc::new(Book {
            key: key.to_owned(),
            epoch,
            sent,
            single,
            losses,
            streams: Mutex::new(Vec::new()),
            settled: Mutex::new(std::collections::VecDeque::new()),
            ended: Mutex::new(ended),
            heard: AtomicU32::new(0),
            started: Instant::now(),
            retire,
        });
        let prefix = format!("{key}/@in/");
        let watched = Arc::clone(&book);
        let watcher = session
            .liveliness()
            .declare_subscriber(format!("{key}/@in/**"))
            .history(true)
            .callback(move |sample| {
                if let Some(id) = sample.key_expr().as_str().strip_prefix(&prefix) {
                    watched.token(id, sample.kind());
                    // An inlet gone may be counted now, or one come asked.
                    watched.sent.nudge();
                }
            })
            .wait()
            .map_err(crate::Error::zenoh("watch the inlets' liveliness"))?;
        let stop = Arc::new(AtomicBool::new(false));
        let (stopped, asked, on) = (Arc::clone(&stop), Arc::clone(&book), session.clone());
        let thread = std::thread::Builder::new()
            .name(format!("cool-net:ack:{key}"))
            .spawn(move || {
                // When it last asked, and the newest number it saw sent and when.
                let mut last = Instant::now();
                let mut seen = (asked.sent(), Instant::now());
                while !stopped.load(Ordering::Acquire) {
                    let mut next = Instant::now() + ACK_PERIOD;
                    asked.sent.looking();
                    let sent = asked.sent();
                    if sent != seen.0 {
                        seen = (sent, Instant::now());
                    }
                    if !asked.is_empty() {
                        if asked.wants_asking(last.elapsed(), seen.1.elapsed()) {
                            asked.ask(&on);
                            last = Instant::now();
                        }
                        asked.settle(false);
                    }
                    if asked.idle() {
                        // Until a send, a token, or the stop (which unparks too); the
                        // next look a period after, as if it had looked all along.
                        asked
                            .sent
                            .sleep(|| asked.idle() && !stopped.load(Ordering::Acquire));
                        next = Instant::now() + ACK_PERIOD;
                    }
                    // Parking may end early (a Zenoh wait unparks this thread too):
                    // only a stop or the period's end counts.
                    while !stopped.load(Ordering::Acquire) {
                        let left = next.saturating_duration_since(Instant::now());
                        if left.is_zero() {
                            break;
                        }
                        std::thread::park_timeout(left);
                    }
                }
            })
            .map_err(crate::Error::spawn("ack"))?;
        Ok(OutletLedger {
            book,
            session: session.clone(),
            stop,
            thread: Some(thread),
            watcher: Some(watcher),
        })
    }
}

impl Drop for OutletLedger {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            thread.thread().unpark();
            let _ = thread.join();
        }
        drop(self.watcher.take());
        // Ask until the live inlets have acknowledged everything, or a round brings
        // nothing new (an inlet that does not answer is not waited for again).
        let mut before = self.book.acknowledged_total();
        for _ in 0..FINAL_ROUNDS {
            if self.book.is_empty() || self.book.caught_up() {
                break;
            }
            self.book.ask(&self.session);
            let now = self.book.acknowledged_total();
            if now == before {
                break;
            }
            before = now;
        }
        self.book.settle(true);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use coolbot::port::{InputPort, TickIn};

    fn book(single: bool) -> (Book, TickIn) {
        let losses = TickIn::new();
        (
            Book {
                key: "k".to_owned(),
                epoch: 7,
                sent: Arc::new(Sent::default()),
                single,
                losses: losses.erased(),
                streams: Mutex::new(Vec::new()),
                settled: Mutex::new(std::collections::VecDeque::new()),
                ended: Mutex::new(Vec::new()),
                heard: AtomicU32::new(0),
                started: Instant::now(),
                retire: None,
            },
            losses,
        )
    }

    fn had(first: u64, newest: u64) -> Vec<Had> {
        vec![Had {
            epoch: 7,
            first,
            newest,
            received: newest - first + 1,
            missing: 0,
        }]
    }

    #[test]
    fn an_inlet_restarted_on_its_node_is_counted_up_to_its_successors_first() {
        let (book, losses) = book(false);
        book.token("station/in/aaa", SampleKind::Put);
        book.sent.set(10);
        book.acknowledged("station/in", &("aaa".to_owned(), had(1, 6)));
        book.sent.set(12);
        book.token("station/in/aaa", SampleKind::Delete);
        book.settle(false);
        assert_eq!(losses.overflows(), 0, "not known to have ended yet");
        book.token("station/in/bbb", SampleKind::Put);
        book.sent.set(20);
        book.acknowledged("station/in", &("bbb".to_owned(), had(14, 20)));
        book.settle(false);
        // 7..=13: after what `aaa` acknowledged, before what `bbb` first received.
        assert_eq!(losses.overflows(), 7);
        book.settle(true);
        assert_eq!(losses.overflows(), 7, "`bbb` acknowledged everything");
    }

    #[test]
    fn an_outlet_asks_only_while_an_inlet_has_not_acknowledged_everything_sent() {
        let (book, _) = book(false);
        // Asked at all, however long ago the last round.
        let asks = || book.wants_asking(ASK_PATIENCE, Duration::ZERO);
        assert!(!asks(), "no inlet, nothing sent");
        book.token("station/in/aaa", SampleKind::Put);
        assert!(!asks(), "a newcomer was sent nothing yet");
        book.sent.set(3);
        assert!(asks(), "three numbers not acknowledged");
        book.acknowledged("station/in", &("aaa".to_owned(), had(1, 2)));
        assert!(asks(), "one number not acknowledged");
        book.acknowledged("station/in", &("aaa".to_owned(), had(1, 3)));
        assert!(!asks(), "everything acknowledged: an idle bridge");
        // The link breaks: no live inlet to ask; it comes back behind.
        book.token("station/in/aaa", SampleKind::Delete);
        book.sent.set(5);
        assert!(!asks(), "no live inlet");
        book.token("station/in/aaa", SampleKind::Put);
        assert!(asks(), "back, and two numbers behind");
        book.acknowledged("station/in", &("aaa".to_owned(), had(1, 5)));
        assert!(!asks());
        *lock(&book.ended) = vec![(3, 40)];
        assert!(asks(), "a killed predecessor to report");
    }

    #[test]
    fn an_outlet_asks_when_an_inlet_is_far_behind_or_behind_for_long_or_the_stream_pauses() {
        let (book, _) = book(false);
        let (soon, sending) = (ACK_PERIOD, Duration::ZERO);
        book.token("station/in/aaa", SampleKind::Put);
        book.token("robot/in/bbb", SampleKind::Put);
        assert!(!book.wants_asking(ASK_PATIENCE, ASK_QUIET), "nothing sent");
        book.sent.set(ASK_BEHIND - 1);
        assert!(
            !book.wants_asking(soon, sending),
            "a few behind, asked lately, still sending"
        );
        assert!(
            book.wants_asking(ASK_PATIENCE, sending),
            "a few behind, for long"
        );
        assert!(
            book.wants_asking(soon, ASK_QUIET),
            "a few behind, the stream paused"
        );
        book.sent.set(ASK_BEHIND);
        assert!(book.wants_asking(soon, sending), "far behind");
        book.acknowledged("station/in", &("aaa".to_owned(), had(1, ASK_BEHIND)));
        assert!(
            book.wants_asking(soon, sending),
            "the other inlet is still far behind"
        );
        book.acknowledged("robot/in", &("bbb".to_owned(), had(1, 2)));
        assert!(
            !book.wants_asking(soon, sending),
            "the farthest is a few behind"
        );
        book.acknowledged("robot/in", &("bbb".to_owned(), had(1, ASK_BEHIND)));
        assert!(!book.wants_asking(ASK_PATIENCE, ASK_QUIET), "caught up");
        *lock(&book.ended) = vec![(3, 40)];
        assert!(
            book.wants_asking(soon, sending),
            "a killed predecessor to report"
        );
    }

    #[test]
    fn an_outlet_whose_inlets_have_everything_and_nothing_to_report_is_idle() {
        let (book, _) = book(false);
        assert!(book.idle(), "no inlet");
        book.token("station/in/aaa", SampleKind::Put);
        assert!(book.idle(), "nothing sent");
        book.sent.set(3);
        assert!(!book.idle(), "behind");
        book.acknowledged("station/in", &("aaa".to_owned(), had(1, 3)));
        assert!(book.idle(), "caught up");
        *lock(&book.ended) = vec![(3, 40)];
        assert!(!book.idle(), "a killed predecessor to report");
    }

    /// Runs `body` with `sent` on a thread of its own, as the ledger's; the flag says
    /// that `body` returned.
    fn ledger_thread(
        sent: &Arc<Sent>,
        body: impl FnOnce(&Sent) + Send + 'static,
    ) -> (JoinHandle<()>, Arc<AtomicBool>) {
        let (done, sent) = (Arc::new(AtomicBool::new(false)), Arc::clone(sent));
        let flag = Arc::clone(&done);
        let thread = std::thread::spawn(move || {
            body(&sent);
            flag.store(true, Ordering::Release);
        });
        (thread, done)
    }

    /// Whether `done` is set within a generous deadline (polled).
    fn within_deadline(done: &AtomicBool) -> bool {
        let deadline = Instant::now() + Duration::from_secs(10);
        while !done.load(Ordering::Acquire) && Instant::now() < deadline {
            std::thread::yield_now();
        }
        done.load(Ordering::Acquire)
    }

    #[test]
    fn a_send_wakes_the_ledger_thread_asleep() {
        let sent = Arc::new(Sent::default());
        let (thread, done) = ledger_thread(&sent, |sent| {
            // Asleep for as long as nothing was sent (a spurious wake-up sleeps again).
            while sent.get() == 0 {
                sent.sleep(|| sent.get() == 0);
            }
        });
        let deadline = Instant::now() + Duration::from_secs(10);
        while !sent.asleep.load(Ordering::Acquire) {
            assert!(Instant::now() < deadline, "the thread never slept");
            std::thread::yield_now();
        }
        sent.set(1);
        let woke = within_deadline(&done);
        if !woke {
            // Not left parked: the test fails below.
            sent.count.store(1, Ordering::Release);
            thread.thread().unpark();
        }
        thread.join().unwrap();
        assert!(woke, "the send did not wake the thread");
        assert!(!sent.asleep.load(Ordering::Acquire));
    }

    #[test]
    fn a_token_that_came_since_the_last_look_keeps_the_ledger_thread_awake() {
        let sent = Arc::new(Sent::default());
        let (thread, done) = ledger_thread(&sent, |sent| {
            sent.looking();
            // A token comes while the thread looks, before it sleeps.
            sent.nudge();
            sent.sleep(|| true);
        });
        let awake = within_deadline(&done);
        // Never left parked, whatever the outcome.
        thread.thread().unpark();
        thread.join().unwrap();
        assert!(awake, "the thread slept with a token to look at");
    }

    #[test]
    fn an_inlet_whose_token_lingers_after_its_successors_appeared_is_counted_too() {
        let (book, losses) = book(false);
        book.token("station/in/aaa", SampleKind::Put);
        book.sent.set(10);
        book.acknowledged("station/in", &("aaa".to_owned(), had(1, 6)));
        book.sent.set(12);
        // The node's next process declares its token before the old one's lease ends.
        book.token("station/in/bbb", SampleKind::Put);
        book.sent.set(15);
        book.acknowledged("station/in", &("bbb".to_owned(), had(13, 15)));
        book.settle(false);
        assert_eq!(losses.overflows(), 0, "`aaa` may still be alive");
        book.token("station/in/aaa", SampleKind::Delete);
        book.sent.set(20);
        book.settle(false);
        // 7..=12: after what `aaa` acknowledged, before what `bbb` first received.
        assert_eq!(losses.overflows(), 6);
        book.acknowledged("station/in", &("bbb".to_owned(), had(13, 20)));
        book.settle(true);
        assert_eq!(losses.overflows(), 6, "`bbb` acknowledged everything");
    }

    #[test]
    fn a_report_is_retired_after_every_known_inlet_heard_it_three_rounds_in_a_row() {
        let (mut book, _) = book(false);
        let retired = Arc::new(AtomicU32::new(0));
        let count = Arc::clone(&retired);
        book.retire = Some(Box::new(move || {
            count.fetch_add(1, Ordering::AcqRel);
        }));
        *lock(&book.ended) = vec![(3, 40)];
        let heard = |ids: &[&str]| ids.iter().map(|&id| id.to_owned()).collect::<HashSet<_>>();
        // Too soon after the outlet started: its peers may not all be found yet.
        book.token("a/in/aaa", SampleKind::Put);
        for _ in 0..RETIRE_ROUNDS {
            book.after_round(&heard(&["a/in/aaa"]));
        }
        assert_eq!(*lock(&book.ended), [(3, 40)], "not before RETIRE_AFTER");
        book.started = Instant::now()
            .checked_sub(RETIRE_AFTER)
            .expect("a monotonic clock that far back");
        // `aaa` did not answer: the rounds count again.
        book.after_round(&heard(&[]));
        book.after_round(&heard(&["a/in/aaa"]));
        book.after_round(&heard(&["a/in/aaa"]));
        // A newcomer: the rounds count again from it (a third round heard by all
        // retires nothing).
        book.token("b/in/bbb", SampleKind::Put);
        book.after_round(&heard(&["a/in/aaa", "b/in/bbb"]));
        assert_eq!(*lock(&book.ended), [(3, 40)], "counted from the newcomer");
        book.after_round(&heard(&["a/in/aaa"])); // `bbb` did not answer: again
        book.after_round(&heard(&["a/in/aaa", "b/in/bbb"]));
        book.after_round(&heard(&["a/in/aaa", "b/in/bbb"]));
        // `bbb`'s link breaks: it may still have to hear the report.
        book.token("b/in/bbb", SampleKind::Delete);
        book.after_round(&heard(&["a/in/aaa"]));
        assert_eq!(*lock(&book.ended), [(3, 40)]);
        assert_eq!(retired.load(Ordering::Acquire), 0);
        book.token("b/in/bbb", SampleKind::Put);
        for _ in 0..RETIRE_ROUNDS {
            book.after_round(&heard(&["a/in/aaa", "b/in/bbb"]));
        }
        assert!(lock(&book.ended).is_empty(), "retired");
        assert_eq!(retired.load(Ordering::Acquire), 1);
        book.after_round(&heard(&["a/in/aaa", "b/in/bbb"]));
        assert_eq!(retired.load(Ordering::Acquire), 1, "once");
    }

    /// An inlet's ledger, and its `network` and `resets` inputs.
    fn inlet() -> (InletLedger, TickIn, TickIn) {
        let (network, resets) = (TickIn::new(), TickIn::new());
        let ledger = InletLedger::new(
            Arc::new(network.erased()),
            Arc::new(resets.erased()),
            "k".to_owned(),
        );
        (ledger, network, resets)
    }

    #[test]
    fn numbers_from_the_network_never_overflow_a_count() {
        let (ledger, network, resets) = inlet();
        ledger.received(9, u64::MAX - 5);
        ledger.received(9, u64::MAX);
        ledger.received(9, u64::MAX);
        assert_eq!(network.overflows(), 4, "MAX-4..MAX-1");
        let (_, counted) = ledger.answer("p", &[(9, u64::MAX), (9, u64::MAX)]);
        assert_eq!(counted, 0, "nothing after the newest");
        ledger.received(3, u64::MAX - 1);
        let (_, counted) = ledger.answer("p", &[(3, u64::MAX)]);
        assert_eq!(counted, 1);
        ledger.received(4, u64::MAX);
        ledger.received(4, 1);
        ledger.received(4, 2);
        ledger.received(4, u64::MAX - 1);
        assert_eq!(network.overflows(), 5);
        assert_eq!(resets.overflows(), 2, "to 1, then to MAX-1");
        let (book, _) = book(false);
        book.token("a/in/aaa", SampleKind::Put);
        book.token("b/in/bbb", SampleKind::Put);
        book.acknowledged("a/in", &("aaa".to_owned(), had(u64::MAX, u64::MAX)));
        book.acknowledged("b/in", &("bbb".to_owned(), had(1, 5)));
        assert_eq!(book.acknowledged_total(), u64::MAX);
    }

    #[test]
    fn a_jump_beyond_the_window_is_one_reset_and_the_stream_counts_on() {
        let (ledger, network, resets) = inlet();
        for seq in 1..=3 {
            ledger.received(9, seq);
        }
        // A stray number far ahead (a forged message): one reset, nothing missing.
        ledger.received(9, 1_000_000_000_000);
        assert_eq!((network.overflows(), resets.overflows()), (0, 1));
        // The stream goes on from where it was, and its gaps count again.
        ledger.received(9, 4);
        ledger.received(9, 6);
        assert_eq!((network.overflows(), resets.overflows()), (1, 1), "5");
        // What the outlet is told: the stream as it is, the stray left out.
        let (answer, _) = ledger.answer("p", &[]);
        let (_, had): Ack = codec::decode(&answer, MAX_ACK).unwrap();
        assert_eq!((had[0].newest, had[0].received, had[0].missing), (6, 6, 1));
    }

    #[test]
    fn epochs_made_up_one_message_each_never_push_out_a_stream() {
        let (ledger, network, resets) = inlet();
        for seq in 1..=3 {
            ledger.received(9, seq);
        }
        // A peer puts one message each of more epochs than the inlet remembers.
        for epoch in 100..100 + 2 * MAX_EPOCHS as u64 {
            ledger.received(epoch, u64::MAX - epoch);
        }
        // Then a number of the stream's epoch out of the window, and the stream
        // goes on (5: 4 was lost on the way).
        ledger.received(9, 1 << 40);
        ledger.received(9, 5);
        ledger.received(9, 6);
        assert_eq!((network.overflows(), resets.overflows()), (1, 1));
        let (answer, _) = ledger.answer("p", &[]);
        let (_, had): Ack = codec::decode(&answer, MAX_ACK).unwrap();
        assert_eq!(had.len(), MAX_EPOCHS);
        let stream = had.iter().find(|h| h.epoch == 9).expect("the stream kept");
        assert_eq!((stream.first, stream.newest, stream.missing), (1, 6, 1));
    }

    #[test]
    fn the_window_is_the_largest_gap_counted_missing() {
        let (ledger, network, resets) = inlet();
        ledger.received(9, 1);
        ledger.received(9, 1 + WINDOW);
        assert_eq!(network.overflows(), WINDOW - 1);
        ledger.received(9, 2 + 2 * WINDOW);
        assert_eq!((network.overflows(), resets.overflows()), (WINDOW - 1, 1));
    }

    #[test]
    fn a_numbering_that_really_moved_costs_one_reset_and_counts_on_from_there() {
        let (ledger, network, resets) = inlet();
        ledger.received(9, 1);
        let far = 10 * WINDOW;
        ledger.received(9, far);
        ledger.received(9, far + 2);
        ledger.received(9, far + 3);
        assert_eq!(resets.overflows(), 1);
        assert_eq!(network.overflows(), 1, "far + 1");
        // Behind the stream by more than the window: a reset too.
        ledger.received(9, 2);
        ledger.received(9, far + 5);
        assert_eq!((network.overflows(), resets.overflows()), (2, 2), "far + 4");
    }

    #[test]
    fn an_inlet_counts_once_what_an_ended_epoch_sent_and_it_never_received() {
        let (ledger, network, resets) = inlet();
        for seq in 1..=5 {
            ledger.received(9, seq);
        }
        let (_, counted) = ledger.answer("p", &[(9, 8), (4, 100)]);
        assert_eq!(counted, 3, "6, 7, 8 (epoch 4 it never had)");
        let (_, again) = ledger.answer("p", &[(9, 8)]);
        assert_eq!(again, 0, "counted once");
        assert_eq!((network.overflows(), resets.overflows()), (3, 0));
    }

    #[test]
    fn a_report_beyond_the_window_is_one_reset_however_often_it_comes() {
        let (ledger, network, resets) = inlet();
        ledger.received(9, 1);
        ledger.received(5, 1);
        for _ in 0..3 {
            let (_, counted) = ledger.answer("p", &[(9, u64::MAX), (u64::MAX, 3), (4, 1 << 40)]);
            assert_eq!(counted, 0);
        }
        assert_eq!((network.overflows(), resets.overflows()), (0, 1));
        let (_, counted) = ledger.answer("p", &[(9, 1_000_000_000_000), (5, 2 + WINDOW)]);
        assert_eq!(counted, 0);
        assert_eq!(resets.overflows(), 3, "another number, another reset");
        // The epochs count on as before.
        let (_, counted) = ledger.answer("p", &[(9, 4), (5, 1 + WINDOW)]);
        assert_eq!(counted, 3 + WINDOW);
        ledger.received(9, 5);
        assert_eq!(network.overflows(), 3 + WINDOW);
    }

    #[test]
    fn a_link_that_comes_back_with_the_same_process_counts_nothing_at_the_outlet() {
        let (book, losses) = book(true);
        book.token("station/in/aaa", SampleKind::Put);
        book.sent.set(10);
        book.acknowledged("station/in", &("aaa".to_owned(), had(1, 5)));
        book.token("station/in/aaa", SampleKind::Delete);
        book.sent.set(20);
        book.token("station/in/aaa", SampleKind::Put);
        book.acknowledged("station/in", &("aaa".to_owned(), had(1, 20)));
        book.settle(true);
        assert_eq!(losses.overflows(), 0);
    }

    #[test]
    fn on_a_queue_key_an_inlet_that_starts_receiving_replaces_the_one_gone() {
        let (book, losses) = book(true);
        book.token("a/in/aaa", SampleKind::Put);
        book.sent.set(10);
        book.acknowledged("a/in", &("aaa".to_owned(), had(1, 8)));
        book.token("a/in/aaa", SampleKind::Delete);
        book.token("b/in/bbb", SampleKind::Put);
        book.sent.set(30);
        book.settle(false);
        assert_eq!(
            losses.overflows(),
            0,
            "its successor has received nothing yet"
        );
        book.acknowledged("b/in", &("bbb".to_owned(), had(12, 30)));
        book.settle(false);
        assert_eq!(losses.overflows(), 3, "9, 10, 11");
    }

    #[test]
    fn a_successor_that_acknowledged_nothing_owns_all_after_it_was_seen() {
        let (book, losses) = book(true);
        book.token("sink/in/aaa", SampleKind::Put);
        book.sent.set(10);
        book.acknowledged("sink/in", &("aaa".to_owned(), had(1, 8)));
        book.token("sink/in/aaa", SampleKind::Delete);
        book.sent.set(12);
        book.token("sink/in/bbb", SampleKind::Put); // seen at 12
        book.sent.set(20);
        book.token("sink/in/bbb", SampleKind::Delete); // never acknowledged
        book.sent.set(25);
        book.token("sink/in/ccc", SampleKind::Put); // seen at 25
        book.sent.set(40);
        book.acknowledged("sink/in", &("ccc".to_owned(), had(27, 40)));
        book.settle(false);
        // aaa: 9..=12; bbb: 13..=26 (up to before ccc's first).
        assert_eq!(losses.overflows(), 4 + 14);
    }

    #[test]
    fn tokens_made_up_and_withdrawn_do_not_pile_up() {
        let (book, losses) = book(false);
        book.sent.set(10);
        // Each under a node name of its own (a node's next process would end the
        // ones before).
        for n in 0..4 * MAX_GONE {
            let id = format!("fuzz{n}/in/p");
            book.token(&id, SampleKind::Put);
            book.token(&id, SampleKind::Delete);
            book.settle(false);
        }
        assert!(
            lock(&book.streams).len() <= MAX_GONE,
            "{} inlets kept",
            lock(&book.streams).len()
        );
        // Nothing was sent while they were there.
        assert_eq!(losses.overflows(), 0);
        book.settle(true);
        assert!(lock(&book.streams).is_empty());
    }

    #[test]
    fn an_inlet_gone_without_successor_is_counted_when_the_outlet_stops() {
        let (book, losses) = book(false);
        book.token("a/in/aaa", SampleKind::Put);
        book.sent.set(10);
        book.token("a/in/aaa", SampleKind::Delete);
        book.sent.set(40);
        book.settle(false);
        assert_eq!(losses.overflows(), 0);
        book.settle(true);
        assert_eq!(
            losses.overflows(),
            10,
            "never acknowledged: all it was sent"
        );
    }
}
