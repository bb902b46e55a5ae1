//! Prompts that a Ctrl-C ends (issue 10).
//!
//! `install_ctrl_c` turns Ctrl-C into a `stop` flag, so the default SIGINT no longer ends the
//! process, and a read blocked on stdin cannot be woken. [`PromptInput`] therefore reads stdin
//! on one helper thread per process, one line at a time, and waits for each line in steps of
//! [`POLL`] while watching `stop`: once it is set, the prompt ends with [`Interrupted`]
//! (nothing moved). The helper thread is shared by every prompt of the process (the UR5e's
//! `yes` and the guided session's answers), so no line is lost between them; a line typed
//! before a prompt is the answer to the next one, as a terminal would have it.
//!
//! [`PromptInput`] is a `BufRead`, so the session's prompting code takes it as it takes any
//! reader; tests give it scripted or never-answering readers and their own flag.

use std::io::{self, BufRead, Read};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Mutex, OnceLock};
use std::time::Duration;

use crate::Error;

/// How often a waiting prompt looks at the stop flag [s]: 50 ms, well under a reaction time.
pub(crate) const POLL: Duration = Duration::from_millis(50);

/// A prompt ended by Ctrl-C (the stop flag) before its answer came.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Interrupted;

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("interrupted (Ctrl-C) at the prompt")
    }
}

impl std::error::Error for Interrupted {}

/// Whether `e` (anywhere in its chain, also inside an `io::Error`) is [`Interrupted`].
pub(crate) fn is_interrupted(e: &Error) -> bool {
    crate::error::causes(e).any(|c| {
        c.is::<Interrupted>()
            || c.downcast_ref::<io::Error>()
                .and_then(io::Error::get_ref)
                .is_some_and(|inner| inner.is::<Interrupted>())
    })
}

/// Lines from a reader thread: `Ok(line)` with its newline, an error, or the end (the sender
/// dropped).
type Lines = Receiver<io::Result<Vec<u8>>>;

/// Starts a thread that sends `reader`'s lines to the returned receiver until the end or an
/// error. A thread that cannot be started gives an ended receiver (every prompt then reads
/// the end of the input: nothing is confirmed).
fn spawn_reader(mut reader: impl BufRead + Send + 'static) -> Lines {
    let (tx, rx) = mpsc::channel();
    let _ = std::thread::Builder::new()
        .name("prompt-input".into())
        .spawn(move || {
            loop {
                let mut line = Vec::new();
                match reader.read_until(b'\n', &mut line) {
                    Ok(0) => return,
                    Ok(_) => {
                        if tx.send(Ok(line)).is_err() {
                            return;
                        }
                    }
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                    Err(e) => {
                        let _ = tx.send(Err(e));
                        return;
                    }
                }
            }
        });
    rx
}

/// The process's stdin reader, started on first use.
fn stdin_lines() -> &'static Mutex<Lines> {
    static STDIN: OnceLock<Mutex<Lines>> = OnceLock::new();
    STDIN.get_or_init(|| Mutex::new(spawn_reader(io::BufReader::new(io::stdin()))))
}

enum Source {
    Stdin,
    #[cfg(test)]
    Own(Mutex<Lines>),
}

/// A `BufRead` over stdin (or, for tests, any reader) that ends with [`Interrupted`] (as an
/// `io::Error` of kind `Other`) once `stop` is set while it waits for a line.
pub(crate) struct PromptInput<'a> {
    source: Source,
    stop: &'a AtomicBool,
    line: Vec<u8>,
    pos: usize,
    ended: bool,
}

impl std::fmt::Debug for PromptInput<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PromptInput")
            .field("stdin", &matches!(self.source, Source::Stdin))
            .field("ended", &self.ended)
            .finish_non_exhaustive()
    }
}

impl<'a> PromptInput<'a> {
    /// The process's stdin, watching `stop`.
    pub(crate) fn stdin(stop: &'a AtomicBool) -> Self {
        Self::with(Source::Stdin, stop)
    }

    /// `reader` read on its own thread, watching `stop` (tests).
    #[cfg(test)]
    pub(crate) fn spawn(reader: impl BufRead + Send + 'static, stop: &'a AtomicBool) -> Self {
        Self::with(Source::Own(Mutex::new(spawn_reader(reader))), stop)
    }

    fn with(source: Source, stop: &'a AtomicBool) -> Self {
        Self {
            source,
            stop,
            line: Vec::new(),
            pos: 0,
            ended: false,
        }
    }

    /// Waits for the next line: `Ok(true)` with it in `self.line`, `Ok(false)` at the end.
    fn next_line(&mut self) -> io::Result<bool> {
        let lines = match &self.source {
            Source::Stdin => stdin_lines(),
            #[cfg(test)]
            Source::Own(l) => l,
        };
        loop {
            if self.stop.load(Ordering::Relaxed) {
                return Err(io::Error::other(Interrupted));
            }
            let next = lines
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .recv_timeout(POLL);
            match next {
                Ok(Ok(line)) => {
                    self.line = line;
                    self.pos = 0;
                    return Ok(true);
                }
                Ok(Err(e)) => return Err(e),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return Ok(false),
            }
        }
    }
}

impl Read for PromptInput<'_> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = {
            let available = self.fill_buf()?;
            let n = available.len().min(buf.len());
            buf[..n].copy_from_slice(&available[..n]);
            n
        };
        self.consume(n);
        Ok(n)
    }
}

impl BufRead for PromptInput<'_> {
    fn fill_buf(&mut self) -> io::Result<&[u8]> {
        if self.pos >= self.line.len() && !self.ended && !self.next_line()? {
            self.ended = true;
            self.line.clear();
            self.pos = 0;
        }
        Ok(self.line.get(self.pos..).unwrap_or_default())
    }

    fn consume(&mut self, amt: usize) {
        self.pos = (self.pos + amt).min(self.line.len());
    }
}

/// One line from `input` (with its newline); `None` when the prompt was interrupted. The end
/// of the input is an error (nothing to confirm with).
pub(crate) fn line_or_stop(input: &mut impl BufRead) -> crate::Result<Option<String>> {
    let mut line = String::new();
    match input.read_line(&mut line) {
        Ok(0) => Err(Error::data("the input", "ended before an answer")),
        Ok(_) => Ok(Some(line)),
        Err(e) if e.get_ref().is_some_and(|i| i.is::<Interrupted>()) => Ok(None),
        Err(e) => Err(Error::io("read the answer from", Path::new("stdin"))(e)),
    }
}

/// One line from stdin, giving up when `stop` is set (Ctrl-C): `None` then (see the module
/// docs).
pub(crate) fn read_line_or_stop(stop: &AtomicBool) -> crate::Result<Option<String>> {
    line_or_stop(&mut PromptInput::stdin(stop))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reader that never answers until the test drops `release` (then it ends).
    fn never_answers() -> (impl BufRead + Send + 'static, mpsc::Sender<()>) {
        struct Never(mpsc::Receiver<()>);
        impl Read for Never {
            fn read(&mut self, _: &mut [u8]) -> io::Result<usize> {
                let _ = self.0.recv();
                Ok(0)
            }
        }
        let (release, rx) = mpsc::channel();
        (io::BufReader::new(Never(rx)), release)
    }

    #[test]
    fn lines_pass_through_in_order_and_the_end_is_an_error() {
        let stop = AtomicBool::new(false);
        let mut input = PromptInput::spawn(io::Cursor::new("yes\nno\n"), &stop);
        assert_eq!(line_or_stop(&mut input).unwrap().as_deref(), Some("yes\n"));
        assert_eq!(line_or_stop(&mut input).unwrap().as_deref(), Some("no\n"));
        let e = line_or_stop(&mut input).unwrap_err().to_string();
        assert!(e.contains("ended"), "{e}");
    }

    #[test]
    fn ctrl_c_ends_a_prompt_that_has_no_answer() {
        // At a077dd5 the `yes` prompt read stdin directly and a Ctrl-C (which only sets the
        // flag) left it waiting for ever.
        let stop = AtomicBool::new(false);
        let (reader, release) = never_answers();
        let mut input = PromptInput::spawn(reader, &stop);
        std::thread::scope(|s| {
            s.spawn(|| {
                std::thread::sleep(3 * POLL);
                stop.store(true, Ordering::Relaxed);
            });
            assert_eq!(line_or_stop(&mut input).unwrap(), None);
        });
        // The same through any `BufRead` user: an error that says so.
        let mut line = String::new();
        let e = Error::io("read", Path::new("stdin"))(input.read_line(&mut line).unwrap_err());
        assert!(is_interrupted(&e), "{e}");
        assert!(e.with_causes().to_string().contains("interrupted"), "{e}");
        assert!(!is_interrupted(&Error::data("stdin", "other")));
        drop(release);
    }
}
