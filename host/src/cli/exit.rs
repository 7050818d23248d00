//! The exit statuses of `motorlink`: one per kind of outcome (the values of BSD's `sysexits.h`
//! where one fits), so a script can tell a usage error from a refused frame from a missing device.
//!
//! Every verb returns a [`Run`]: `Ok(exit)` when it ran to its verdict (which may still be a
//! failure: a board that refused, a scenario whose expectation failed), `Err(failure)` when it
//! stopped with a message for standard error.

use crate::cli::device::Verdict;
use crate::transport::LinkError;

/// How a run ended, as the process exit status. The values never change meaning.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Exit {
    /// 0: done (the board answered and did it; the frame decoded; every expectation held).
    Ok = 0,
    /// 1: a check or a run failed: the board refused the command, a scenario expectation failed.
    Failed = 1,
    /// 64 (`EX_USAGE`): a bad argument or option; nothing was opened or sent.
    Usage = 64,
    /// 65 (`EX_DATAERR`): the data was refused: a bad frame, hex or JSON, a number a frame cannot
    /// carry, a capture without a frame, a scenario file that does not parse.
    DataRefused = 65,
    /// 66 (`EX_NOINPUT`): an input file (capture, scenario) is missing or cannot be read.
    NoInput = 66,
    /// 69 (`EX_UNAVAILABLE`): the device cannot be opened, or it did not reply in time.
    Unavailable = 69,
    /// 74 (`EX_IOERR`): reading or writing failed during the run (the device, an output file).
    Io = 74,
    /// 75 (`EX_TEMPFAIL`): nothing came: a silent port, no frame within the run; try again.
    Temporary = 75,
}

impl Exit {
    /// The process exit status.
    pub const fn code(self) -> u8 {
        self as u8
    }
}

impl From<Verdict> for Exit {
    /// done → [`Exit::Ok`], refused → [`Exit::Failed`], no reply → [`Exit::Unavailable`].
    fn from(v: Verdict) -> Self {
        match v {
            Verdict::Done => Self::Ok,
            Verdict::Refused => Self::Failed,
            Verdict::NoReply => Self::Unavailable,
        }
    }
}

/// A run that stopped: the message for standard error and the exit status.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Failure {
    /// The exit status.
    pub exit: Exit,
    /// What went wrong and what to do about it.
    pub message: String,
}

impl Failure {
    /// A failure with `exit` and `message`.
    pub fn new(exit: Exit, message: impl Into<String>) -> Self {
        Self {
            exit,
            message: message.into(),
        }
    }

    /// [`Exit::Usage`].
    pub fn usage(message: impl Into<String>) -> Self {
        Self::new(Exit::Usage, message)
    }

    /// [`Exit::DataRefused`].
    pub fn data(message: impl Into<String>) -> Self {
        Self::new(Exit::DataRefused, message)
    }
}

/// What a verb returns.
pub type Run = Result<Exit, Failure>;

/// Gives an error its exit status.
pub trait OrExit<T> {
    /// The error as a [`Failure`] with `exit`.
    fn or_exit(self, exit: Exit) -> Result<T, Failure>;
}

impl<T> OrExit<T> for Result<T, String> {
    fn or_exit(self, exit: Exit) -> Result<T, Failure> {
        self.map_err(|m| Failure::new(exit, m))
    }
}

impl<T> OrExit<T> for Result<T, LinkError> {
    fn or_exit(self, exit: Exit) -> Result<T, Failure> {
        self.map_err(|e| Failure::new(exit, e.to_string()))
    }
}

/// The table printed by `motorlink --help` (also in host/README.md).
pub const TABLE: &str = "Exit status (every verb):
  0   done: the board answered and did it, the frame decoded, every expectation held
  1   a check or run failed: the board refused (ACK result != 0, cmd_success 0), a scenario
      expectation failed
  64  usage: a bad argument or option (nothing was opened or sent)
  65  data refused: a bad frame, hex or JSON, a number a frame cannot carry, a capture without
      a frame, a scenario file that does not parse
  66  input missing: a capture or scenario file that does not exist or cannot be read
  69  unavailable: the device cannot be opened, or it did not reply in time
  74  I/O error during the run: the device failed, an output file cannot be written
  75  temporary: nothing came (a silent port, no frame within the run); try again";

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_the_documented_ones() {
        // sysexits.h: EX_USAGE 64, EX_DATAERR 65, EX_NOINPUT 66, EX_UNAVAILABLE 69,
        // EX_IOERR 74, EX_TEMPFAIL 75.
        let table = [
            (Exit::Ok, 0),
            (Exit::Failed, 1),
            (Exit::Usage, 64),
            (Exit::DataRefused, 65),
            (Exit::NoInput, 66),
            (Exit::Unavailable, 69),
            (Exit::Io, 74),
            (Exit::Temporary, 75),
        ];
        for (e, code) in table {
            assert_eq!(e.code(), code);
            let line = TABLE
                .lines()
                .find(|l| l.trim_start().starts_with(&format!("{code} ")))
                .unwrap();
            assert!(!line.is_empty());
        }
        assert_eq!(Exit::from(Verdict::Done), Exit::Ok);
        assert_eq!(Exit::from(Verdict::Refused), Exit::Failed);
        assert_eq!(Exit::from(Verdict::NoReply), Exit::Unavailable);
    }
}
