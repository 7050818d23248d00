//! `cargo xtask fw-variant <qemu|usb>`: the firmware images of a feature variant (`qemu`: every
//! image built for the emulator; `usb`: the `cdc` image speaking over USB CDC ACM), built in the
//! workspace's own target directory so that they share every dependency already built for the
//! board images, copied to `target/<variant>/thumbv7em-none-eabihf/firmware/`, and the board
//! images put back in place.
//!
//! A feature build writes its images where the board's are (`target/thumbv7em-none-eabihf/
//! firmware/`); the last step rebuilds the board images (`cargo fw`, a relink at most, since cargo
//! keeps each feature set's objects apart), so that what is there to flash is always the board's.
//! A variant built in a target directory of its own rebuilt every dependency (151 s for `qemu`,
//! 85 s for `usb`, in a fresh clone).

use std::path::{Path, PathBuf};

/// The command line, for usage messages.
pub const USAGE: &str = "cargo xtask fw-variant <qemu|usb>";

/// The images of each variant.
fn images(variant: &str) -> Option<&'static [&'static str]> {
    match variant {
        "qemu" => Some(&["amr-spi", "cdc", "teensy", "pi-spi"]),
        "usb" => Some(&["cdc"]),
        _ => None,
    }
}

/// Runs `cargo build -p firmware --profile firmware --target thumbv7em-none-eabihf` with `extra`.
fn build_firmware(root: &Path, extra: &[&str]) -> Result<(), String> {
    let mut args = vec![
        "build",
        "-p",
        "firmware",
        "--profile",
        "firmware",
        "--target",
        "thumbv7em-none-eabihf",
    ];
    args.extend_from_slice(extra);
    crate::cargo::cargo(root, &args)
}

/// Builds `variant`'s images, copies them to `target/<variant>/thumbv7em-none-eabihf/firmware/`
/// and rebuilds the board images; returns the directory the variant's images are in.
pub fn build(root: &Path, variant: &str) -> Result<PathBuf, String> {
    let Some(bins) = images(variant) else {
        return Err(format!(
            "no firmware variant '{variant}' (qemu, usb)\nusage: {USAGE}"
        ));
    };
    let board = root.join("target/thumbv7em-none-eabihf/firmware");
    let dest = root
        .join("target")
        .join(variant)
        .join("thumbv7em-none-eabihf/firmware");
    let copied = (|| {
        let mut extra = vec!["--features", variant];
        for bin in bins {
            extra.extend(["--bin", bin]);
        }
        build_firmware(root, &extra)?;
        std::fs::create_dir_all(&dest)
            .map_err(|e| format!("cannot create {}: {e}", dest.display()))?;
        for bin in bins {
            std::fs::copy(board.join(bin), dest.join(bin))
                .map_err(|e| format!("cannot copy the {variant} image {bin}: {e}"))?;
        }
        Ok::<(), String>(())
    })();
    // The board images back in place, whether or not the variant built.
    let restored = build_firmware(root, &[]).map_err(|e| {
        format!(
            "{e}: {} may hold {variant} images; run `cargo fw` before flashing",
            board.display()
        )
    });
    copied.and(restored).map(|()| dest)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_variant_names_its_images_and_others_are_refused() {
        assert_eq!(images("qemu").map(<[_]>::len), Some(4));
        assert_eq!(images("usb"), Some(&["cdc"][..]));
        assert_eq!(images("board"), None);
        let r = build(Path::new("/nonexistent"), "board");
        assert!(
            r.as_ref()
                .is_err_and(|e| e.contains("no firmware variant 'board'")),
            "{r:?}"
        );
    }
}
