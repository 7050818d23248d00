//! The `cdc` image's USB variant (feature `usb`): seed 001 over USB CDC ACM on OTG FS (PA11 D−,
//! PA12 D+), the Jetson's `/dev/ttyACM0`.
//!
//! ```text
//!  OTG_FS IRQ ─► link_usb (priority 2): poll the device; every byte read ─► CdcLinkTask::on_byte;
//!                queued replies ─► the bulk IN endpoint (what it takes now; the rest at the next IRQ)
//! ```
//! A reply the endpoint cannot take stays queued (`mcu::serial::TxQueue`, which drops and counts
//! whole frames only when full); a host that has not opened the port leaves replies queued until
//! the queue is full, then they are counted as dropped.

use stm32f4xx_hal::otg_fs::{UsbBus, USB};
use usb_device::bus::UsbBusAllocator;
use usb_device::device::{StringDescriptors, UsbDevice, UsbDeviceBuilder, UsbVidPid};
use usbd_serial::SerialPort;

/// The USB bus type of this board.
pub type Bus = UsbBus<USB>;

/// Endpoint memory of the OTG FS peripheral, words.
pub const EP_WORDS: usize = 1024;

/// The bus allocator's static home and the endpoint memory (an `init` local of the image).
pub type Mem = (Option<UsbBusAllocator<Bus>>, [u32; EP_WORDS]);
/// [`Mem`] before `init`.
pub const MEM_INIT: Mem = (None, [0; EP_WORDS]);

/// The CDC ACM port and its device.
pub struct UsbLink {
    dev: UsbDevice<'static, Bus>,
    port: SerialPort<'static, Bus>,
}

impl UsbLink {
    /// Takes the OTG FS peripheral (its pins already in their USB function) and the static
    /// memory of the bus, and enumerates as a CDC ACM device (pid.codes test VID/PID
    /// 0x1209/0x0001).
    pub fn new(usb: USB, mem: &'static mut Mem) -> Self {
        let (slot, ep) = mem;
        let bus: &'static UsbBusAllocator<Bus> = slot.insert(UsbBus::new(usb, ep));
        let port = SerialPort::new(bus);
        let strings = StringDescriptors::default()
            .manufacturer("motor-controller")
            .product("seed 001 motor board")
            .serial_number("0001");
        let builder = || UsbDeviceBuilder::new(bus, UsbVidPid(0x1209, 0x0001));
        // The strings fit the builder's table (one language); were they refused, the device
        // would still enumerate, without them.
        let dev = builder()
            .strings(&[strings])
            .unwrap_or_else(|_| builder())
            .device_class(usbd_serial::USB_CLASS_CDC)
            .build();
        Self { dev, port }
    }

    /// Services the device; hands every received byte to `on_byte`.
    pub fn poll(&mut self, mut on_byte: impl FnMut(u8)) {
        if !self.dev.poll(&mut [&mut self.port]) {
            return;
        }
        let mut buf = [0u8; 64];
        while let Ok(n) = self.port.read(&mut buf) {
            if n == 0 {
                break;
            }
            for &b in buf.get(..n).unwrap_or(&[]) {
                on_byte(b);
            }
        }
    }

    /// Writes what the endpoint takes now from `q`.
    pub fn pump<const CAP: usize>(&mut self, q: &mut mcu::serial::TxQueue<CAP>) {
        let mut chunk = [0u8; 64];
        loop {
            let mut n = 0usize;
            for slot in chunk.iter_mut() {
                let Some(b) = q.pop() else { break };
                *slot = b;
                n = n.saturating_add(1);
            }
            if n == 0 {
                return;
            }
            let sent = self.port.write(chunk.get(..n).unwrap_or(&[])).unwrap_or(0);
            if sent < n {
                // Put back what the endpoint did not take, in order, ahead of the rest.
                q.push_front_all(chunk.get(sent..n).unwrap_or(&[]));
                return;
            }
        }
    }
}
