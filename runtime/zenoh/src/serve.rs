//! A thread that serves what a channel brings, one request at a time, and sleeps
//! in between: a node's replier. Dropping the [`Server`] stops the thread (the
//! requests still queued are dropped) and joins it.

use std::thread::JoinHandle;

use crossbeam_channel::{Receiver, Sender};

use crate::Error;

/// A serving thread; stopped and joined when dropped.
pub(crate) struct Server {
    /// Dropped to stop the thread (which sleeps until a request or this).
    stop: Option<Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Server {
    /// Start the thread `name` (`what` names it in a spawn error), calling `serve`
    /// with each request of `requests` until the server is dropped or every sender
    /// of `requests` is.
    pub(crate) fn start<T: Send + 'static>(
        name: String,
        what: &'static str,
        requests: Receiver<T>,
        mut serve: impl FnMut(T) + Send + 'static,
    ) -> Result<Server, Error> {
        let (stop, stopped) = crossbeam_channel::bounded::<()>(0);
        let thread = std::thread::Builder::new()
            .name(name)
            .spawn(move || {
                loop {
                    crossbeam_channel::select_biased! {
                        recv(stopped) -> _ => break,
                        recv(requests) -> request => match request {
                            Ok(request) => serve(request),
                            Err(_) => break,
                        },
                    }
                }
            })
            .map_err(Error::spawn(what))?;
        Ok(Server {
            stop: Some(stop),
            thread: Some(thread),
        })
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}
