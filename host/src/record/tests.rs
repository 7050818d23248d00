//! Fault names, odometry by hand, the CSV shape, the file formats.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use super::*;

#[test]
fn fault_flags_by_name() {
    assert_eq!(fault_names(0), "");
    // COMM_LOST (bit 4) | BRAKE_LATCHED (bit 9) = 16 + 512.
    assert_eq!(fault_names(528), "COMM_LOST|BRAKE_LATCHED");
    assert_eq!(fault_names(1 << 20), "BIT20");
}

#[test]
fn odometry_from_encoder_counts_by_hand() {
    let mut o = Odometer::new(&DiffDrive::DEFAULT, 4096);
    o.update([100, 100]);
    assert_eq!((o.x, o.y, o.theta), (0.0, 0.0, 0.0));
    // One wheel revolution each: 2π · 0.08 m = 0.502655 m straight ahead (the geometry is held
    // to 15 µm: r = 0.0800018 m, 2.3e-5 more, 1.2e-5 m on a revolution).
    o.update([100 + 4096, 100 + 4096]);
    assert!((o.x - 0.502_655).abs() < 2e-5, "{o:?}");
    assert!(o.y.abs() < 1e-12 && o.theta.abs() < 1e-12);
    // Right wheel a quarter turn forward, left a quarter back: θ += 2 · (π/2 · 0.08) / 0.40 = 0.628 rad.
    o.update([100 + 4096 - 1024, 100 + 4096 + 1024]);
    assert!((o.theta - 0.628_318).abs() < 1e-4, "{o:?}");
    assert!((o.x - 0.502_655).abs() < 2e-5, "{o:?}");
    // Counters wrap without a jump.
    let mut w = Odometer::new(&DiffDrive::DEFAULT, 4096);
    w.update([i32::MAX, i32::MAX]);
    w.update([i32::MIN, i32::MIN]);
    assert!((w.x - 0.502_655 / 4096.0).abs() < 1e-8, "{w:?}");
}

#[test]
fn the_file_name_chooses_the_format() {
    assert_eq!(
        Format::from_path(Path::new("a.mcap")).unwrap(),
        Format::Mcap
    );
    assert_eq!(Format::from_path(Path::new("b.CSV")).unwrap(), Format::Csv);
    let e = Format::from_path(Path::new("c.bag")).unwrap_err();
    assert!(e.to_string().contains(".mcap"), "{e}");
}

#[test]
fn plans_refuse_bad_numbers() {
    assert_eq!(RecordPlan::new(2.0, 0.3, 0.0).unwrap().exchanges, 2000);
    assert!(RecordPlan::new(-1.0, 0.0, 0.0).is_err());
    assert!(RecordPlan::new(1.0, f64::NAN, 0.0).is_err());
    assert!(!RecordPlan::new(1.0, 0.0, 0.0).unwrap().arms());
}

#[test]
fn every_csv_row_has_the_header_s_columns() {
    let columns = CSV_HEADER.split(',').count();
    let mut link = Link::new(SimMcu::lockstep(), Bridge::new(Default::default()));
    let mut rec = Recorder::create(
        &std::env::temp_dir().join(format!("motorlink-row-{}.csv", std::process::id())),
        RecordConfig::default(),
    )
    .unwrap();
    link.bridge.arm(0);
    for k in 0..5 {
        let d = link.sim_cycle().unwrap();
        let truth = (k % 2 == 0).then(|| link.transport.truth());
        let row = rec.row(&link, (0.1, 0.0), &d, truth).unwrap();
        assert_eq!(csv_line(&row).split(',').count(), columns, "{row:?}");
    }
    // A slot that held no feedback.
    link.last_exchange.as_mut().unwrap().rx = [0; FRAME_LEN];
    let row = rec.row(&link, (0.0, 0.0), &[], None).unwrap();
    assert!(row.other.is_some());
    assert_eq!(csv_line(&row).split(',').count(), columns);
}
