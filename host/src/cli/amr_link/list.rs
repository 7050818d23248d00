//! `motorlink list`: the serial ports (with their USB vendor, product and serial number) and the
//! spidev devices of this machine, with the link kinds each can serve.

use serde::Serialize;

/// The pid.codes test VID/PID the seed 001 firmware enumerates with (firmware/src/board/usb.rs).
pub const SEED001_USB: (u16, u16) = (0x1209, 0x0001);

/// PJRC's vendor ID (Teensy boards, seed 003).
pub const PJRC_VID: u16 = 0x16C0;

/// One device found.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Found {
    /// Device path.
    pub path: String,
    /// "usb", "pci", "bluetooth", "spidev", "other".
    pub bus: &'static str,
    /// USB vendor ID (hex), if USB.
    pub vid: Option<String>,
    /// USB product ID (hex), if USB.
    pub pid: Option<String>,
    /// USB manufacturer string.
    pub manufacturer: Option<String>,
    /// USB product string.
    pub product: Option<String>,
    /// USB serial number.
    pub serial_number: Option<String>,
    /// The `--kind` values this device can serve, most likely first.
    pub kinds: Vec<&'static str>,
    /// Why those kinds.
    pub note: String,
}

/// The link kinds of a serial port, from its USB IDs (if any) and its name.
pub fn serial_kinds(path: &str, usb: Option<(u16, u16)>) -> (Vec<&'static str>, String) {
    match usb {
        Some(ids) if ids == SEED001_USB => (
            vec!["serial"],
            "the USB CDC four-motor board's own USB CDC (1209:0001)".into(),
        ),
        Some((vid, _)) if vid == PJRC_VID => (
            vec!["teensy"],
            "a PJRC Teensy (16c0): the Teensy serial link".into(),
        ),
        Some(_) => (
            vec!["serial", "teensy"],
            "a USB serial adapter: a USB CDC four-motor board on its UART, or a Teensy serial link"
                .into(),
        ),
        None if path.contains("ttyACM") => (vec!["serial", "teensy"], "a CDC ACM device".into()),
        None => (
            vec!["serial", "teensy"],
            "a UART: a USB CDC four-motor board or a Teensy serial link on its pins".into(),
        ),
    }
}

/// The link kinds of a spidev device.
pub fn spidev_kinds() -> (Vec<&'static str>, String) {
    (
        vec!["spi", "pi-spi"],
        "spidev: the AMR SPI link (--kind spi: arm, drive, top, ...) or the Raspberry Pi SPI link (--kind pi-spi)".into(),
    )
}

/// Every serial port the serialport crate enumerates (sysfs), then every `/dev/spidev*`.
pub fn discover() -> Result<Vec<Found>, String> {
    let mut found = Vec::new();
    // The enumeration reads /sys/class/tty; a machine without it has no serial ports to list.
    let ports = if std::path::Path::new("/sys/class/tty").is_dir() {
        serialport::available_ports().map_err(|e| format!("cannot enumerate serial ports: {e}"))?
    } else {
        Vec::new()
    };
    for p in ports {
        let mut f = Found {
            path: p.port_name.clone(),
            bus: "other",
            vid: None,
            pid: None,
            manufacturer: None,
            product: None,
            serial_number: None,
            kinds: Vec::new(),
            note: String::new(),
        };
        let mut usb = None;
        match p.port_type {
            serialport::SerialPortType::UsbPort(u) => {
                f.bus = "usb";
                f.vid = Some(format!("{:04x}", u.vid));
                f.pid = Some(format!("{:04x}", u.pid));
                f.manufacturer = u.manufacturer;
                f.product = u.product;
                f.serial_number = u.serial_number;
                usb = Some((u.vid, u.pid));
            }
            serialport::SerialPortType::PciPort => f.bus = "pci",
            serialport::SerialPortType::BluetoothPort => f.bus = "bluetooth",
            serialport::SerialPortType::Unknown => {}
        }
        (f.kinds, f.note) = serial_kinds(&f.path, usb);
        found.push(f);
    }
    let mut spi: Vec<String> = match std::fs::read_dir("/dev") {
        Ok(rd) => rd
            .filter_map(Result::ok)
            .filter_map(|e| e.file_name().into_string().ok())
            .filter(|n| n.starts_with("spidev"))
            .map(|n| format!("/dev/{n}"))
            .collect(),
        Err(_) => Vec::new(),
    };
    spi.sort();
    for path in spi {
        let (kinds, note) = spidev_kinds();
        found.push(Found {
            path,
            bus: "spidev",
            vid: None,
            pid: None,
            manufacturer: None,
            product: None,
            serial_number: None,
            kinds,
            note,
        });
    }
    Ok(found)
}

/// `list` as text.
pub fn text(found: &[Found]) -> String {
    if found.is_empty() {
        return "no serial port and no spidev device found (a QEMU -serial pty is not listed: give its /dev/pts/N directly; for no hardware at all use --sim)".into();
    }
    let mut t = String::new();
    for f in found {
        let usb = match (&f.vid, &f.pid) {
            (Some(v), Some(p)) => format!(
                " {v}:{p} {}{}",
                f.product.as_deref().unwrap_or("?"),
                f.serial_number
                    .as_deref()
                    .map(|s| format!(" (serial {s})"))
                    .unwrap_or_default()
            ),
            _ => String::new(),
        };
        t.push_str(&format!(
            "{:20} {:9}{usb}\n  --kind {}: {}\n",
            f.path,
            f.bus,
            f.kinds.join(" | "),
            f.note
        ));
    }
    t
}

/// `list --json`.
pub fn json(found: &[Found]) -> serde_json::Value {
    serde_json::json!({ "devices": found })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn kinds_follow_the_usb_ids() {
        assert_eq!(
            serial_kinds("/dev/ttyACM0", Some((0x1209, 0x0001))).0,
            ["serial"]
        );
        assert_eq!(
            serial_kinds("/dev/ttyACM0", Some((0x16c0, 0x0483))).0,
            ["teensy"]
        );
        assert_eq!(
            serial_kinds("/dev/ttyUSB0", Some((0x0403, 0x6001))).0,
            ["serial", "teensy"]
        );
        assert!(spidev_kinds().0.contains(&"spi"));
    }

    #[test]
    fn text_names_every_device_and_its_kinds() {
        let (kinds, note) = spidev_kinds();
        let f = Found {
            path: "/dev/spidev0.0".into(),
            bus: "spidev",
            vid: None,
            pid: None,
            manufacturer: None,
            product: None,
            serial_number: None,
            kinds,
            note,
        };
        let t = text(&[f]);
        assert!(t.contains("/dev/spidev0.0"));
        assert!(t.contains("spi | pi-spi"));
        assert!(text(&[]).contains("--sim"));
    }
}
