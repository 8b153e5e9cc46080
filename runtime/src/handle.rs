//! A component's handle: its control port `c` ([`Handle::command`]) and monitoring
//! port `m` ([`Handle::snapshot`], [`Handle::subscribe`], [`Handle::wait_for`]), and
//! the messages a command travels in.

use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::Receiver;

use crate::clock::{AnswerNotice, ClockWait, Waited};
use crate::mailbox::{Closer, Mailbox, PostError};
use crate::monitor::{Command, Monitor, MonitorEvent, Rejected, Shared, Subscription, Timeout};
use crate::table::{Controllable, State};

fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A command on its way to the component, with the channel for its answer.
pub(crate) struct ControlMessage {
    /// Boxed: a queued message stays small whatever the largest command.
    pub(crate) command: Box<Command>,
    /// Given by the component's compound's adaptation (its supervisor managing the
    /// instance's level), not by anyone else (an operator, a policy, a test).
    pub(crate) by_supervisor: bool,
    /// Where the component answers: closed when the message is dropped.
    pub(crate) reply: Closer<Reply>,
    /// `PENDING`, then `TAKEN` by the component or `WITHDRAWN` by the sender.
    pub(crate) claim: Arc<AtomicU8>,
    /// A sender waiting in a virtual clock's time: told of each answer, and when the
    /// message is dropped (after `reply`, declared before it, closes the answers).
    pub(crate) notice: Option<NoticeOnDrop>,
}

/// A message's [`AnswerNotice`], given once more when the message is dropped.
pub(crate) struct NoticeOnDrop(pub(crate) AnswerNotice);

impl Drop for NoticeOnDrop {
    fn drop(&mut self) {
        self.0.answered();
    }
}

/// How many answers one command gets at most (accepted, taking clock time, done).
pub(crate) const REPLIES: usize = 3;

pub(crate) const PENDING: u8 = 0;
pub(crate) const TAKEN: u8 = 1;
pub(crate) const WITHDRAWN: u8 = 2;

impl Posted {
    /// Withdraw it unless the component took it already; whether it was withdrawn.
    pub(crate) fn withdraw(&self) -> bool {
        self.claim
            .compare_exchange(PENDING, WITHDRAWN, Ordering::AcqRel, Ordering::Acquire)
            .is_ok()
    }
}

impl ControlMessage {
    /// A message carrying `command`, and where its answers arrive.
    pub(crate) fn new(command: Command, by_supervisor: bool) -> (Self, Arc<Mailbox<Reply>>) {
        let (reply, answers) = crate::mailbox::answers(REPLIES);
        let message = ControlMessage {
            command: Box::new(command),
            by_supervisor,
            reply,
            claim: Arc::new(AtomicU8::new(PENDING)),
            notice: None,
        };
        (message, answers)
    }

    /// Post `answer`, and tell a sender waiting in a virtual clock's time.
    pub(crate) fn answer(&self, answer: Reply) {
        let _ = self.reply.post(answer);
        if let Some(notice) = &self.notice {
            notice.0.answered();
        }
    }

    /// Whether its sender withdrew it (it waits in the queue to be dropped).
    pub(crate) fn withdrawn(&self) -> bool {
        self.claim.load(Ordering::Acquire) == WITHDRAWN
    }

    /// Claim the message for execution; false if the sender withdrew it.
    pub(crate) fn take(&self) -> bool {
        self.claim
            .compare_exchange(PENDING, TAKEN, Ordering::AcqRel, Ordering::Acquire)
            .is_ok()
    }
}

/// A command queued by [`Handle::post`], whose answers [`Handle::finish`] waits for
/// (or [`Handle::poll`] looks at).
pub(crate) struct Posted {
    command: Command,
    answers: Arc<Mailbox<Reply>>,
    claim: Arc<AtomicU8>,
    deadline: Instant,
    /// [`Handle::poll`] saw the component take it (the transition is under way).
    accepted: bool,
    /// Posted by a section on a virtual clock: it waits in the clock's time, until the
    /// clock's deadline here (then, once its system shuts down, in real time until
    /// `deadline`); the command's number.
    on_clock: Option<(ClockWait, Instant, u64)>,
    /// The component's id on the virtual clock.
    target: Option<u64>,
}

/// The component's answers to one command.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Reply {
    /// The command is legal; for a state change, the transition starts now.
    Accepted,
    /// A section of the transition takes time of a virtual clock (`Context::spend`):
    /// the command counts as taken.
    TakingClockTime,
    /// The transition finished.
    Done,
    /// The command was rejected.
    Rejected(String),
}

/// Why a command did not go through, before it is rendered into [`Rejected::reason`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Refusal {
    /// The component's thread has not been spawned.
    NotStarted,
    /// The command was given on the component's own thread.
    OwnThread,
    /// The component's control queue is full.
    QueueFull,
    /// The component's thread has ended.
    Ended,
    /// The component did not take the command within the handle's command timeout
    /// (a section still running); the command was withdrawn.
    Busy,
    /// The component rejected it, for this reason.
    Rejected(String),
}

impl Refusal {
    /// The reason as [`Rejected::reason`] words it.
    fn describe(self, timeout: Duration) -> String {
        match self {
            Refusal::NotStarted => "the component has not been started (System::start)".to_owned(),
            Refusal::OwnThread => {
                "a component cannot command itself from its own thread (use Context::end to finish)"
                    .to_owned()
            }
            Refusal::QueueFull | Refusal::Ended => {
                "the component's thread has ended or its control queue is full".to_owned()
            }
            Refusal::Busy => format!(
                "busy: the component did not take the command within {timeout:?}; withdrawn"
            ),
            Refusal::Rejected(reason) => reason,
        }
    }
}

/// The control port `c` and monitoring port `m` of one component. Cheap to clone,
/// `Send`; any number of handles may exist.
#[derive(Clone)]
pub struct Handle {
    pub(crate) name: Arc<str>,
    pub(crate) shared: Arc<Shared>,
    /// The control port's queue, closed when the component's thread ends.
    pub(crate) control: Arc<Mailbox<ControlMessage>>,
    /// The component's doorbell: rung after each command is queued.
    pub(crate) bell: Arc<crate::wake::Doorbell>,
    pub(crate) join: Arc<Mutex<Option<JoinHandle<()>>>>,
    pub(crate) command_timeout: Duration,
    /// A compound's instances' handles, in declaration order (empty for an atomic
    /// component). They hold the instances' ports only, never the compound's inner
    /// system: the instances' threads end with the compound whatever handles remain.
    pub(crate) instances: Arc<[Handle]>,
    /// The component's input ports by name, in declaration order (a recording's
    /// replay feeds them).
    pub(crate) inputs: Arc<[(&'static str, crate::port::ErasedInput)]>,
    /// The component's output ports by name, in declaration order (recorder taps).
    pub(crate) outputs: Arc<[(&'static str, crate::port::ErasedOutput)]>,
    /// The component's static shape (a compound's as built: exported ports, mapped
    /// variables).
    pub(crate) spec: &'static crate::Spec,
}

impl std::fmt::Debug for Handle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Handle({})", self.name)
    }
}

impl Handle {
    /// The component instance's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The component's static shape: its type, states, ports, variables (with their
    /// kinds and types) and timing; a compound's as built, with its exported ports
    /// and mapped variables.
    pub fn spec(&self) -> &'static crate::Spec {
        self.spec
    }

    /// The names of a compound's instances (its direct ones, in declaration order);
    /// empty for an atomic component.
    pub fn instances(&self) -> Vec<String> {
        self.instances.iter().map(|h| h.name.to_string()).collect()
    }

    /// The control and monitoring ports of the instance at `path` inside this
    /// compound: instance names separated by `.`, through nested compounds (`"base"`,
    /// `"base.motion"`). `None` for an atomic component, an unknown name or a malformed
    /// path (empty, or with an empty segment).
    ///
    /// The handle returned is the instance's own (commands reach it, snapshots are
    /// live), as [`CompoundBuilder::instance_handle`](crate::CompoundBuilder::instance_handle)
    /// gives on the builder. Commanding an instance goes around its compound's
    /// supervisor, which sees the change as it sees any of the instance's changes
    /// (a fault forced this way is handled by the instance's policy).
    pub fn instance(&self, path: &str) -> Option<Handle> {
        let mut handle = self;
        for name in path.split('.') {
            handle = handle.instances.iter().find(|h| &*h.name == name)?;
        }
        Some(handle.clone())
    }

    /// The instances inside this compound (paths through nested compounds) whose
    /// threads have not ended (a thread's end closes its control queue).
    pub(crate) fn unended_instances(&self) -> Vec<String> {
        let mut unended = Vec::new();
        for instance in self.instances.iter() {
            if !instance.control.is_closed() {
                unended.push(instance.name.to_string());
            }
            for inner in instance.unended_instances() {
                unended.push(format!("{}.{inner}", instance.name));
            }
        }
        unended
    }

    /// A handle whose commands wait at most `timeout` for the component.
    pub fn with_command_timeout(mut self, timeout: Duration) -> Handle {
        self.command_timeout = timeout;
        self
    }

    fn rejected(&self, command: &Command, reason: impl Into<String>) -> Rejected {
        Rejected {
            component: self.name.to_string(),
            command: crate::ranges::excerpt_debug(command, crate::ranges::EXCERPT_CHARS),
            reason: reason.into(),
        }
    }

    /// Send a command through the control port and wait for its answer.
    ///
    /// The component answers when its thread next looks at its control port: at once
    /// if it is waiting, or when the user section it is running returns. A state change
    /// returns after the transition has run (its sections and hooks), so the monitor
    /// shows the new state; `SetState(Dead)` also joins the thread. If the component does
    /// not take the command within the handle's command timeout (a section running
    /// longer than that), the command is withdrawn and rejected as busy; if it took it
    /// but the transition is still running at the timeout, `Ok` is returned and the
    /// transition completes later.
    pub fn command(&self, command: Command) -> Result<(), Rejected> {
        let posted = self.post(command)?;
        self.finish(posted)
    }

    /// The first half of [`Handle::command`]: queue the command and ring the
    /// component, without waiting ([`System::run_all`](crate::System::run_all) posts to
    /// every component before it waits for any).
    pub(crate) fn post(&self, command: Command) -> Result<Posted, Rejected> {
        let rendered = command.clone();
        self.post_command(command)
            .map_err(|refusal| self.rejected(&rendered, refusal.describe(self.command_timeout)))
    }

    /// [`Handle::post`] by a sender on a virtual clock (`clock_wait`): its
    /// [`Handle::poll`] looks at the answers until the clock moves, and its deadline is
    /// in the clock's time.
    pub(crate) fn post_on_clock(
        &self,
        command: Command,
        clock_wait: Option<&ClockWait>,
    ) -> Result<Posted, Rejected> {
        let rendered = command.clone();
        self.post_waiting(command, false, clock_wait)
            .map_err(|refusal| self.rejected(&rendered, refusal.describe(self.command_timeout)))
    }

    /// [`Handle::post`], with why it failed as a [`Refusal`].
    pub(crate) fn post_command(&self, command: Command) -> Result<Posted, Refusal> {
        self.post_from(command, false)
    }

    /// [`Handle::post`] for a compound's adaptation managing this instance's level
    /// (`crate::compound::adaptation`): the instance tells it from an operator's.
    pub(crate) fn post_by_supervisor(&self, command: Command) -> Result<Posted, Rejected> {
        let rendered = command.clone();
        self.post_from(command, true)
            .map_err(|refusal| self.rejected(&rendered, refusal.describe(self.command_timeout)))
    }

    fn post_from(&self, command: Command, by_supervisor: bool) -> Result<Posted, Refusal> {
        self.post_waiting(command, by_supervisor, None)
    }

    /// [`Handle::post_from`] by a sender that waits for the answers in the time of a
    /// virtual clock (`clock_wait`: a supervisor's section).
    fn post_waiting(
        &self,
        command: Command,
        by_supervisor: bool,
        clock_wait: Option<&ClockWait>,
    ) -> Result<Posted, Refusal> {
        if !self.shared.spawned.load(Ordering::Acquire) {
            return Err(Refusal::NotStarted);
        }
        if self.shared.thread.get() == Some(&std::thread::current().id()) {
            // The thread would wait for itself until the timeout.
            return Err(Refusal::OwnThread);
        }
        let deadline = crate::time::later(Instant::now(), self.command_timeout);
        let (mut message, answers) = ControlMessage::new(command.clone(), by_supervisor);
        let on_clock = clock_wait.map(|wait| {
            if let Some(member) = self.shared.clock_member.get() {
                wait.busy(*member);
            }
            let notice = wait.notice();
            let number = notice.command();
            message.notice = Some(NoticeOnDrop(notice));
            let until = crate::time::later(wait.now(), self.command_timeout);
            (wait.clone(), until, number)
        });
        let claim = Arc::clone(&message.claim);
        if let Err(error) = self.post_control(message) {
            if on_clock.is_some() {
                // Marked busy for a command that never came: a turn settles it again.
                self.bell.ring();
            }
            return Err(match error {
                PostError::Full => Refusal::QueueFull,
                PostError::Closed => Refusal::Ended,
            });
        }
        self.bell.ring_command();
        Ok(Posted {
            command,
            answers,
            claim,
            deadline,
            accepted: false,
            on_clock,
            target: self.shared.clock_member.get().copied(),
        })
    }

    /// Queue `message` on the control port. A full queue first drops the commands
    /// their senders withdrew (a component busy in a long section keeps them until it
    /// takes them): they take no room from a later command, `dead` at shutdown
    /// included.
    pub(crate) fn post_control(&self, message: ControlMessage) -> Result<(), PostError> {
        match self.control.post(message) {
            Err((PostError::Full, message)) => {
                if self.control.retain(|queued| !queued.withdrawn()) == 0 {
                    return Err(PostError::Full);
                }
                self.control.post(message).map_err(|(error, _)| error)
            }
            outcome => outcome.map_err(|(error, _)| error),
        }
    }

    /// Look at the answers to `posted`, waiting at most `wait`: `None` while the
    /// component has not finished with it (not taken yet, or its transition still
    /// running) and its deadline has not passed; otherwise its outcome, as
    /// [`Handle::command`] gives it (a command not taken by its deadline is withdrawn
    /// and rejected as busy; one taken whose transition outlasts it counts as done).
    /// For a caller that must not wait for a component that may be busy (a compound's
    /// recovery queue: its thread passes packets on meanwhile).
    pub(crate) fn poll(&self, posted: &mut Posted, wait: Duration) -> Option<Result<(), Rejected>> {
        let until = crate::time::later(Instant::now(), wait);
        loop {
            let answer = match posted.on_clock.take() {
                // Posted on a virtual clock: looked at until the clock moves, in its time
                // (the component answers at the clock's time unless it is taking some).
                Some(on_clock) => {
                    let (wait, _, number) = &on_clock;
                    let answers = &posted.answers;
                    let came = || !answers.is_empty() || answers.is_closed();
                    let moved = crate::time::later(wait.now(), Duration::from_nanos(1));
                    let waited = wait.wait(*number, moved, &came, posted.target);
                    if waited != Waited::Off {
                        posted.on_clock = Some(on_clock);
                    }
                    posted.answers.take_until(Instant::now())
                }
                None => posted.answers.take_until(until),
            };
            match answer {
                Some(Reply::Accepted) => posted.accepted = true,
                // (Taking time of a virtual clock: counts as taken, as in `finish`.)
                Some(Reply::Done | Reply::TakingClockTime) => return Some(Ok(())),
                Some(Reply::Rejected(reason)) => {
                    return Some(Err(self.rejected(&posted.command, reason)));
                }
                None => break,
            }
        }
        // Dropped unanswered and never taken: the component's thread ended with it
        // queued.
        let closed = posted.answers.is_closed();
        if closed && !posted.accepted && posted.claim.load(Ordering::Acquire) == PENDING {
            return Some(Err(self.rejected(
                &posted.command,
                Refusal::Ended.describe(self.command_timeout),
            )));
        }
        let overdue = match &posted.on_clock {
            Some((wait, until, _)) => wait.now() >= *until,
            None => Instant::now() >= posted.deadline,
        };
        if !closed && !overdue {
            return None;
        }
        if posted.accepted {
            return Some(Ok(()));
        }
        match posted
            .claim
            .compare_exchange(PENDING, WITHDRAWN, Ordering::AcqRel, Ordering::Acquire)
        {
            Ok(_) => Some(Err(self.rejected(
                &posted.command,
                Refusal::Busy.describe(self.command_timeout),
            ))),
            // Taken just now: its answers come.
            Err(_) => {
                posted.accepted = true;
                None
            }
        }
    }

    /// The second half of [`Handle::command`]: wait for the answers to `posted`.
    pub(crate) fn finish(&self, posted: Posted) -> Result<(), Rejected> {
        let rendered = posted.command.clone();
        self.finish_command(posted)
            .map_err(|refusal| self.rejected(&rendered, refusal.describe(self.command_timeout)))
    }

    /// [`Handle::finish`], with why it failed as a [`Refusal`].
    pub(crate) fn finish_command(&self, posted: Posted) -> Result<(), Refusal> {
        let is_dead = posted.command == Command::SetState(Controllable::Dead);
        let until = wait_for_answers(posted, self.command_timeout)?;
        if is_dead {
            self.join_if_exited(until);
        }
        Ok(())
    }

    /// [`Handle::command`] with why it failed as a [`Refusal`] (a compound's
    /// supervisor commanding its instances: `crate::commander`), waiting in the time
    /// of a virtual clock with `clock_wait` (a supervisor's section on one).
    pub(crate) fn command_refusable(
        &self,
        command: Command,
        clock_wait: Option<&ClockWait>,
    ) -> Result<(), Refusal> {
        let posted = self.post_waiting(command, false, clock_wait)?;
        self.finish_command(posted)
    }

    /// Wait (until `deadline`) for the thread to end, then join it.
    pub(crate) fn join_if_exited(&self, deadline: Instant) -> Option<Result<(), String>> {
        // The thread's end closes its control queue.
        if !self.control.wait_closed(deadline) {
            return None;
        }
        let handle = lock(&self.join).take()?;
        Some(crate::thread::join(handle))
    }

    /// A copy of everything the monitoring port publishes now.
    pub fn snapshot(&self) -> Monitor {
        self.shared.snapshot()
    }

    /// The default automaton state now.
    pub fn state(&self) -> State {
        self.shared.state()
    }

    /// Whether the component's thread is inside a section that overran its
    /// `max_response` and has not returned yet (the watchdog moved the component to
    /// `running_error`; commands wait until the section returns).
    pub fn is_stuck(&self) -> bool {
        self.shared.stuck.load(Ordering::Acquire)
    }

    /// A new observer: every change from now on, as it happens, up to
    /// [`OBSERVER_CAPACITY`](crate::OBSERVER_CAPACITY) events waiting (beyond that, events are dropped for it:
    /// [`Handle::subscribe_counted`] tells how many).
    pub fn subscribe(&self) -> Receiver<MonitorEvent> {
        self.shared.subscribe().into_events()
    }

    /// [`Handle::subscribe`], with the counts of what was published to this observer
    /// and dropped for it ([`Subscription::dropped`]): an observer that must not lose
    /// events silently (a recorder, a bridge, a live display) uses this.
    pub fn subscribe_counted(&self) -> Subscription {
        self.shared.subscribe()
    }

    /// A new counted observer whose every event also rings `waker` (a recorder or a
    /// compound's supervisor: its thread wakes on each change, no polling).
    pub fn subscribe_waking(&self, waker: crate::wake::Waker) -> Subscription {
        self.shared.subscribe_waking(waker)
    }

    /// Wait until `pred` holds for the monitor, woken by monitoring events (no polling),
    /// for at most `timeout`. `pred` is evaluated on each event, so it should depend on
    /// the monitor only (a change nobody announces does not wake the wait).
    pub fn wait_for(
        &self,
        pred: impl Fn(&Monitor) -> bool,
        timeout: Duration,
    ) -> Result<Monitor, Timeout> {
        let deadline = crate::time::later(Instant::now(), timeout);
        // Most waits are already satisfied: look before subscribing (a subscription
        // allocates a channel and costs every publication a send until it is dropped).
        let monitor = self.snapshot();
        if pred(&monitor) {
            return Ok(monitor);
        }
        // Subscribe, then look again: a change between the two looks is either in the
        // second snapshot or announced on the channel.
        let events = self.shared.subscribe();
        loop {
            let monitor = self.snapshot();
            if pred(&monitor) {
                return Ok(monitor);
            }
            match events.recv_deadline(deadline) {
                Ok(_) => {}
                Err(_) => {
                    let monitor = self.snapshot();
                    if pred(&monitor) {
                        return Ok(monitor);
                    }
                    return Err(Timeout {
                        waited: timeout,
                        last: Box::new(monitor),
                    });
                }
            }
        }
    }

    /// Shorthand: wait until the default automaton is in `state`.
    pub fn wait_state(&self, state: State, timeout: Duration) -> Result<Monitor, Timeout> {
        self.wait_for(|monitor| monitor.state == state, timeout)
    }
}

/// Wait for the answers to `posted`: `Ok` with the time it waited until once the
/// component took the command and finished it (or its transition outlasts the wait,
/// or takes time of a virtual clock: then now); else why not. A command not taken by its
/// deadline is withdrawn (`Busy`); one taken just then is given `timeout` again for
/// its answers.
fn wait_for_answers(posted: Posted, timeout: Duration) -> Result<Instant, Refusal> {
    let Posted {
        answers,
        claim,
        deadline,
        mut on_clock,
        target,
        ..
    } = posted;
    let mut until = deadline;
    // The component took it (its `Accepted` may come after the claim).
    let mut taken = false;
    loop {
        match next_answer(&answers, until, &mut on_clock, target) {
            Some(Reply::Accepted) => taken = true,
            // A section of the transition takes time of a virtual clock: only the
            // clock can end it, and whoever moves the clock may be the one waiting, so
            // the command counts as taken, as one whose transition outlasts its time.
            Some(Reply::Done) => return Ok(until),
            // (Its end is now: a `dead` whose exit section takes the clock's time
            // does not wait for the thread to exit, which only an advance lets it.)
            Some(Reply::TakingClockTime) => return Ok(Instant::now()),
            Some(Reply::Rejected(reason)) => return Err(Refusal::Rejected(reason)),
            // The transition outlasts its time: it counts as taken.
            None if taken => return Ok(until),
            None => {
                // Dropped unanswered and never taken: the component's thread ended
                // with it queued.
                if answers.is_closed() && claim.load(Ordering::Acquire) == PENDING {
                    return Err(Refusal::Ended);
                }
                if claim
                    .compare_exchange(PENDING, WITHDRAWN, Ordering::AcqRel, Ordering::Acquire)
                    .is_ok()
                {
                    return Err(Refusal::Busy);
                }
                // Taken just now: given as long again to finish its transition.
                taken = true;
                until = crate::time::later(Instant::now(), timeout);
                if let Some((wait, clock_until, _)) = &mut on_clock {
                    *clock_until = crate::time::later(wait.now(), timeout);
                }
            }
        }
    }
}

/// The next answer in `answers`, waiting until `until` (real time), or with
/// `on_clock` in the time of a virtual clock until its deadline there; `None` when
/// none came by then (or the component dropped the command unanswered). Once the
/// waiter's system shuts down, the wait goes on in real time.
fn next_answer(
    answers: &Mailbox<Reply>,
    until: Instant,
    on_clock: &mut Option<(ClockWait, Instant, u64)>,
    target: Option<u64>,
) -> Option<Reply> {
    if let Some((wait, clock_until, number)) = on_clock {
        let came = || !answers.is_empty() || answers.is_closed();
        match wait.wait(*number, *clock_until, &came, target) {
            Waited::Answered | Waited::TimedOut => return answers.take_until(Instant::now()),
            Waited::Off => *on_clock = None,
        }
    }
    answers.take_until(until)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `message` as posted, its deadline already past.
    fn overdue(message: &ControlMessage, answers: Arc<Mailbox<Reply>>) -> Posted {
        Posted {
            command: (*message.command).clone(),
            answers,
            claim: Arc::clone(&message.claim),
            deadline: Instant::now(),
            accepted: false,
            on_clock: None,
            target: None,
        }
    }

    fn configure() -> (ControlMessage, Arc<Mailbox<Reply>>) {
        ControlMessage::new(Command::Configure(crate::Value::Unit), false)
    }

    #[test]
    fn a_command_not_taken_by_its_deadline_is_withdrawn() {
        let (message, answers) = configure();
        let posted = overdue(&message, answers);
        assert_eq!(
            wait_for_answers(posted, Duration::from_secs(60)),
            Err(Refusal::Busy)
        );
        assert!(message.withdrawn());
        assert!(!message.take());
    }

    #[test]
    fn a_command_dropped_unanswered_and_never_taken_says_the_component_ended() {
        let (message, answers) = configure();
        let posted = overdue(&message, answers);
        drop(message);
        assert_eq!(
            wait_for_answers(posted, Duration::from_secs(60)),
            Err(Refusal::Ended)
        );
    }

    /// Taken before its deadline, refused after it: the refusal is the outcome (the
    /// wait that follows a command taken just then reads every answer).
    #[test]
    fn a_refusal_after_the_deadline_of_a_command_taken_in_time_is_a_refusal() {
        let (message, answers) = configure();
        assert!(message.take());
        let posted = overdue(&message, answers);
        let component = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(10));
            message.answer(Reply::Rejected("invalid".to_owned()));
        });
        let outcome = wait_for_answers(posted, Duration::from_secs(60));
        component.join().expect("no panic");
        assert_eq!(outcome, Err(Refusal::Rejected("invalid".to_owned())));
    }

    /// A transition whose section takes time of a virtual clock counts as taken at
    /// once, whatever time is left.
    #[test]
    fn a_transition_taking_clock_time_counts_as_taken() {
        let (message, answers) =
            ControlMessage::new(Command::SetState(Controllable::Running), false);
        assert!(message.take());
        message.answer(Reply::Accepted);
        message.answer(Reply::TakingClockTime);
        let mut posted = overdue(&message, answers);
        posted.deadline = crate::time::later(Instant::now(), Duration::from_secs(3_600));
        assert!(wait_for_answers(posted, Duration::from_secs(3_600)).is_ok());
    }
}
