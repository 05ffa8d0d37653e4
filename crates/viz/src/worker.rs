//! A logging thread fed over a channel (the arm's drawing thread, the Bode runs'
//! logging thread): it never stops the run it logs, and a thread that could not start
//! or that panicked is reported once through the recorder's [`Sink`].

use std::sync::mpsc;
use std::thread::JoinHandle;

use crate::Sink;

/// A thread running `body` on the items sent to it; [`Worker::join`] (or dropping it)
/// closes the channel and waits for the thread.
#[derive(Debug)]
pub(crate) struct Worker<T> {
    tx: Option<mpsc::Sender<T>>,
    handle: Option<JoinHandle<()>>,
    sink: Sink,
    /// What the thread does, for the report of a panic ("drawing the arm").
    what: &'static str,
}

impl<T: Send + 'static> Worker<T> {
    /// Starts the thread `name`, or reports why it could not (then `None`: nothing is
    /// logged, the run goes on).
    pub(crate) fn spawn(
        sink: &Sink,
        name: &str,
        what: &'static str,
        body: impl FnOnce(mpsc::Receiver<T>) + Send + 'static,
    ) -> Option<Self> {
        let (tx, rx) = mpsc::channel::<T>();
        match std::thread::Builder::new()
            .name(name.into())
            .spawn(move || body(rx))
        {
            Ok(handle) => Some(Self {
                tx: Some(tx),
                handle: Some(handle),
                sink: sink.clone(),
                what,
            }),
            Err(e) => {
                sink.report(&format!("starting the thread for {what}"), Err(e));
                None
            }
        }
    }
}

impl<T> Worker<T> {
    /// Hands `item` to the thread; false when the thread is gone (it panicked:
    /// [`Worker::join`] reports it).
    pub(crate) fn send(&self, item: T) -> bool {
        self.tx.as_ref().is_some_and(|tx| tx.send(item).is_ok())
    }

    /// Closes the channel and waits for the thread to log what it was given.
    pub(crate) fn join(&mut self) {
        self.tx = None;
        if let Some(handle) = self.handle.take() {
            if handle.join().is_err() {
                self.sink
                    .report(self.what, Err("the logging thread panicked"));
            }
        }
    }
}

impl<T> Drop for Worker<T> {
    fn drop(&mut self) {
        self.join();
    }
}
