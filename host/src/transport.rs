//! Byte transports to the MCU: Linux spidev (seed 000/004) and serial / USB CDC (seed 001/003).

use std::io::{Read, Write};
use std::time::Duration;

/// Why a transfer failed. Each message says what to check.
#[derive(Debug)]
pub enum LinkError {
    /// The device could not be opened.
    Open(String, String),
    /// The device could not be configured.
    Configure(String, String),
    /// A transfer failed.
    Io(String, std::io::Error),
    /// Nothing (or not enough) came back in time.
    Timeout(String, usize),
    /// A serial request got no matching reply in time (device, what was expected).
    NoReply(String, String),
}

impl core::fmt::Display for LinkError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Open(dev, e) => write!(
                f,
                "cannot open {dev}: {e}. Check that the device exists (ls /dev/spidev* /dev/ttyACM* /dev/pts/), that no other program holds it open, that SPI is enabled in the device tree, and that you are in the group owning it (spi or dialout)"
            ),
            Self::Configure(dev, e) => write!(f, "cannot configure {dev}: {e}. Check that the driver supports the settings (SPI: mode 0, 8 bits, 2 MHz; serial: raw 8N1 at the baud rate)"),
            Self::Io(dev, e) => write!(f, "transfer on {dev} failed: {e}. Check the cable and that the MCU is powered"),
            Self::NoReply(dev, what) => write!(f, "{dev}: no {what} before the timeout. Check that the firmware runs, the baud rate, and that the device speaks this protocol"),
            Self::Timeout(dev, n) => write!(f, "{dev}: only {n} bytes came back before the timeout. Check that the MCU firmware is running and the baud rate / wiring"),
        }
    }
}

impl std::error::Error for LinkError {}

/// A full-duplex or request/response byte link.
pub trait Transport {
    /// Sends `tx` and fills `rx` with what comes back (SPI: simultaneously; serial: the reply).
    fn exchange(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError>;
    /// The device name, for messages.
    fn name(&self) -> &str;
}

/// A boxed transport (`Box<dyn Transport + Send>`, as a thread takes it) is a transport.
impl<T: Transport + ?Sized> Transport for Box<T> {
    fn exchange(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
        (**self).exchange(tx, rx)
    }
    fn name(&self) -> &str {
        (**self).name()
    }
}

/// Linux spidev master (`/dev/spidevB.C`), mode 0, 8-bit, MSB first.
pub struct SpiTransport {
    dev: spidev::Spidev,
    path: String,
}

impl SpiTransport {
    /// Opens `path` at `hz`.
    pub fn open(path: &str, hz: u32) -> Result<Self, LinkError> {
        let mut dev =
            spidev::Spidev::open(path).map_err(|e| LinkError::Open(path.into(), e.to_string()))?;
        let opts = spidev::SpidevOptions::new()
            .bits_per_word(8)
            .max_speed_hz(hz)
            .mode(spidev::SpiModeFlags::SPI_MODE_0)
            .build();
        dev.configure(&opts)
            .map_err(|e| LinkError::Configure(path.into(), e.to_string()))?;
        Ok(Self {
            dev,
            path: path.into(),
        })
    }
}

impl Transport for SpiTransport {
    fn exchange(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
        let mut t = spidev::SpidevTransfer::read_write(tx, rx);
        self.dev
            .transfer(&mut t)
            .map_err(|e| LinkError::Io(self.path.clone(), e))
    }

    fn name(&self) -> &str {
        &self.path
    }
}

/// A serial port, USB CDC ACM device (`/dev/ttyACM0`) or pseudo-terminal (`/dev/pts/5`, as QEMU's
/// `-serial pty` creates), raw 8N1.
pub struct SerialTransport {
    port: Box<dyn serialport::SerialPort>,
    path: String,
}

impl SerialTransport {
    /// Opens `path` at `baud` with a read timeout.
    ///
    /// The line is put in raw mode (`cfmakeraw`: no echo, no line editing, no signal characters,
    /// no CR/LF translation, no software flow control), so every byte passes unchanged both ways;
    /// a pty starts in cooked mode with echo on, which would send the MCU's own frames back to it.
    /// The port is opened exclusively (`TIOCEXCL` and `flock`): a second `motorlink` on the same
    /// device is refused instead of interleaving its frames. DTR is left as the kernel sets it (no
    /// modem-control call, which a pty would refuse anyway).
    ///
    /// Bytes that arrived before the open (a pty buffers the MCU's STATUS frames while no process
    /// holds it) are discarded, so the first message read after a request is no stale reply to
    /// somebody else's. Nothing written after the open is lost: the flush happens before it.
    pub fn open(path: &str, baud: u32, timeout: Duration) -> Result<Self, LinkError> {
        let port = serialport::new(path, baud)
            .timeout(timeout)
            .open()
            .map_err(|e| LinkError::Open(path.into(), e.to_string()))?;
        port.clear(serialport::ClearBuffer::Input)
            .map_err(|e| LinkError::Configure(path.into(), e.to_string()))?;
        Ok(Self {
            port,
            path: path.into(),
        })
    }
}

impl Transport for SerialTransport {
    fn exchange(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
        self.port
            .write_all(tx)
            .map_err(|e| LinkError::Io(self.path.clone(), e))?;
        let mut got = 0usize;
        while got < rx.len() {
            let Some(buf) = rx.get_mut(got..) else { break };
            match self.port.read(buf) {
                Ok(0) => break,
                Ok(n) => got = got.saturating_add(n),
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => break,
                Err(e) => return Err(LinkError::Io(self.path.clone(), e)),
            }
        }
        if got < rx.len() {
            return Err(LinkError::Timeout(self.path.clone(), got));
        }
        Ok(())
    }

    fn name(&self) -> &str {
        &self.path
    }
}

/// A byte stream with a read timeout: the serial links (seed 001, seed 003), whose frames carry
/// their own delimiters, so reads return whatever has arrived rather than a fixed-size reply.
pub trait ByteStream {
    /// Writes every byte.
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError>;
    /// Reads what has arrived into `buf`, waiting at most the stream's timeout; `Ok(0)` if nothing came.
    fn read_some(&mut self, buf: &mut [u8]) -> Result<usize, LinkError>;
    /// The device name, for messages.
    fn name(&self) -> &str;
    /// Sets how long [`ByteStream::read_some`] waits; streams without a clock ignore it.
    fn set_read_timeout(&mut self, _timeout: Duration) -> Result<(), LinkError> {
        Ok(())
    }
    /// Discards every byte received and not yet read (stale replies, periodic frames), so the
    /// next read returns only what arrives after this call. Returns how many were discarded.
    fn discard_input(&mut self) -> Result<usize, LinkError>;
}

impl ByteStream for SerialTransport {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.port
            .write_all(bytes)
            .map_err(|e| LinkError::Io(self.path.clone(), e))
    }

    fn read_some(&mut self, buf: &mut [u8]) -> Result<usize, LinkError> {
        match self.port.read(buf) {
            Ok(n) => Ok(n),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => Ok(0),
            Err(e) => Err(LinkError::Io(self.path.clone(), e)),
        }
    }

    fn name(&self) -> &str {
        &self.path
    }

    fn set_read_timeout(&mut self, timeout: Duration) -> Result<(), LinkError> {
        self.port
            .set_timeout(timeout)
            .map_err(|e| LinkError::Configure(self.path.clone(), e.to_string()))
    }
    fn discard_input(&mut self) -> Result<usize, LinkError> {
        let waiting = self.port.bytes_to_read().unwrap_or(0);
        self.port
            .clear(serialport::ClearBuffer::Input)
            .map_err(|e| LinkError::Io(self.path.clone(), std::io::Error::other(e.to_string())))?;
        Ok(usize::try_from(waiting).unwrap_or(usize::MAX))
    }
}

/// An in-memory stream for tests: every write releases the next scripted reply, which is then
/// read back in chunks of at most `chunk` bytes (so frames arrive split across reads).
#[derive(Debug, Default)]
pub struct ScriptedStream {
    /// Everything written so far.
    pub written: Vec<u8>,
    /// Replies still to come, one per write.
    pub replies: std::collections::VecDeque<Vec<u8>>,
    /// Bytes released and not yet read.
    pub pending: std::collections::VecDeque<u8>,
    /// Largest read, bytes (0 is taken as 1).
    pub chunk: usize,
}

impl ScriptedStream {
    /// A stream that answers the n-th write with `replies[n]`, `chunk` bytes per read.
    pub fn new(replies: Vec<Vec<u8>>, chunk: usize) -> Self {
        Self {
            replies: replies.into(),
            chunk,
            ..Self::default()
        }
    }
}

impl ByteStream for ScriptedStream {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.written.extend_from_slice(bytes);
        if let Some(r) = self.replies.pop_front() {
            self.pending.extend(r);
        }
        Ok(())
    }

    fn read_some(&mut self, buf: &mut [u8]) -> Result<usize, LinkError> {
        let n = buf.len().min(self.chunk.max(1)).min(self.pending.len());
        for (d, s) in buf.iter_mut().zip(self.pending.drain(..n)) {
            *d = s;
        }
        Ok(n)
    }

    fn name(&self) -> &str {
        "scripted"
    }
    fn discard_input(&mut self) -> Result<usize, LinkError> {
        let n = self.pending.len();
        self.pending.clear();
        Ok(n)
    }
}

/// A transport that answers with a fixed frame (tests and the loop benchmark).
pub struct NullTransport {
    /// What every exchange returns.
    pub reply: Vec<u8>,
}

impl Transport for NullTransport {
    fn exchange(&mut self, _tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
        for (d, s) in rx
            .iter_mut()
            .zip(self.reply.iter().chain(std::iter::repeat(&0)))
        {
            *d = *s;
        }
        Ok(())
    }

    fn name(&self) -> &str {
        "null"
    }
}

#[cfg(test)]
mod tests;
