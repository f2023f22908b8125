//! Frames proved by their checksums; outcomes computed from other bytes or boards are stale.

use std::fs;

use crc::{CRC_64_XZ, Crc};

use super::*;
use crate::paths;
use crate::test_fixture::{manifest, pixels};
use crate::time::HostTimeUs;
use crate::writer::{FrameRecord, SessionAppender, SessionWriter};

fn session(dir: &Path, frames: u64) {
    let mut w = SessionWriter::create(dir, manifest()).unwrap();
    for id in 0..frames {
        let px = pixels(id);
        w.write_frame(FrameRecord {
            t_host_us: HostTimeUs(id),
            frame_id: id,
            t_camera_ns: None,
            exposure_us: 8000,
            gain_db: 0.0,
            width: 8,
            height: 6,
            pixels: &px,
            flagged: None,
        })
        .unwrap();
    }
    w.finish(HostTimeUs(99), "completed").unwrap();
}

fn frame(dir: &Path, id: u64) -> std::path::PathBuf {
    dir.join(paths::FRAMES).join(paths::frame_file(id))
}

#[test]
fn frames_are_proved_by_the_checksums_their_events_record() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("s");
    session(&dir, 4);
    let s = crate::reader::open(&dir).unwrap();
    let check = s.check_frames();
    assert_eq!(check.current.len(), 4);
    assert!(check.mismatched.is_empty() && check.unrecorded.is_empty());
    assert_eq!(check.refusal(&dir), None);

    // renamed one id off: 1 ← 0's file, 0 gone; 3 from elsewhere
    fs::rename(frame(&dir, 1), tmp.path().join("x")).unwrap();
    fs::rename(frame(&dir, 0), frame(&dir, 1)).unwrap();
    fs::write(frame(&dir, 3), b"\x89PNG another capture").unwrap();
    let check = crate::reader::open(&dir).unwrap().check_frames();
    assert_eq!(
        check.mismatched,
        [
            FrameMismatch {
                frame_id: 1,
                holds_frame: Some(0),
                unreadable: None
            },
            FrameMismatch {
                frame_id: 3,
                holds_frame: None,
                unreadable: None
            }
        ]
    );
    let msg = check.refusal(&dir).unwrap();
    assert!(
        msg.contains("2 of 3 frames are not the ones this session recorded")
            && msg.contains("frame 1 (its file holds frame 0's pixels: renamed?)")
            && msg.contains("frame 3"),
        "{msg}"
    );
}

#[test]
fn a_single_damaged_frame_is_skipped_and_said_not_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("s");
    session(&dir, 4);
    // another capture's valid frame in place of frame 2
    crate::frame_png::write(&frame(&dir, 2), 8, 6, &[7u16; 48]).unwrap();
    let s = crate::reader::open(&dir).unwrap();
    let check = s.check_frames();
    assert!(!check.inconsistent());
    assert_eq!(check.refusal(&dir), None);
    let warning = check.warning().unwrap();
    assert!(
        warning.contains("1 of 4 frames") && warning.contains(": 2;"),
        "{warning}"
    );
    // every stage's loader refuses its pixels, so none pairs them with frame 2's pose
    let e = s.load_frame(&s.frames[2]).unwrap_err().to_string();
    assert!(e.contains("not the ones this session recorded"), "{e}");
    assert!(s.load_frame(&s.frames[1]).is_ok());
}

#[test]
fn a_frame_loaded_with_its_checksum_gives_the_check_s_checksum_of_the_bytes_it_read() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("s");
    session(&dir, 3);
    // frame 1 replaced by another capture's valid frame; frame 2 unreadable
    crate::frame_png::write(&frame(&dir, 1), 8, 6, &[7u16; 48]).unwrap();
    fs::remove_file(frame(&dir, 2)).unwrap();
    fs::create_dir(frame(&dir, 2)).unwrap();
    let s = crate::reader::open(&dir).unwrap();
    let check = s.check_frames();
    for f in s.frames.iter().filter(|f| f.complete) {
        let (crc64, loaded) = s.load_frame_and_crc64(f);
        // the checksum of the bytes read, recorded or not: what tracking says it tracked
        assert_eq!(crc64, check.current[&f.frame_id], "frame {}", f.frame_id);
        assert_eq!(
            loaded.as_ref().map_err(ToString::to_string),
            s.load_frame(f).as_ref().map_err(ToString::to_string),
            "frame {}",
            f.frame_id
        );
        assert_eq!(loaded.is_ok(), f.frame_id == 0, "frame {}", f.frame_id);
    }
    assert_eq!(check.current[&2], None);
    assert_ne!(check.current[&1], check.expected[&1]);
}

#[test]
fn a_session_without_checksums_is_read_and_said_unchecked() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("s");
    session(&dir, 3);
    // an older session: its frame events carry no checksum
    let log = dir.join(paths::EVENTS);
    let text = fs::read_to_string(&log).unwrap();
    let old: Vec<String> = text
        .lines()
        .map(|l| {
            let mut v: serde_json::Value = serde_json::from_str(l).unwrap();
            v.as_object_mut().unwrap().remove("crc64");
            v.to_string()
        })
        .collect();
    fs::write(&log, old.join("\n") + "\n").unwrap();
    fs::write(frame(&dir, 2), b"\x89PNG another capture").unwrap();
    let check = crate::reader::open(&dir).unwrap().check_frames();
    assert!(check.mismatched.is_empty());
    assert_eq!(check.unrecorded, [0, 1, 2]);
    assert_eq!(check.refusal(&dir), None);
    assert!(
        check
            .note()
            .unwrap()
            .contains("3 of 3 frames carry no checksum")
    );
}

#[test]
fn outcomes_computed_from_other_bytes_or_boards_are_stale() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("s");
    session(&dir, 5);
    let s = crate::reader::open(&dir).unwrap();
    let check = s.check_frames();
    let crc = |id: u64| check.current[&id];
    let boards = crate::rig::TrackedBoard {
        name: None,
        family: "tag36h11".into(),
        corners_board_m: Default::default(),
        world_from_board_translation_m: [0.0; 3],
        world_from_board_rotation: [0.0; 3],
    };
    let now = boards_crc64(std::slice::from_ref(&boards));
    let mut wrong = boards.clone();
    wrong.world_from_board_translation_m[0] = 0.1;
    let then_wrong = boards_crc64(&[wrong]);
    let rejected =
        |id: u64, frame_crc64: Option<u64>, boards_crc64: Option<u64>| SessionEvent::PoseRejected {
            t_host_us: HostTimeUs(0),
            frame_id: id,
            reason: "frame not processable".into(),
            from: TrackedFrom {
                frame_crc64,
                boards_crc64,
            },
        };
    let mut log = SessionAppender::open(&dir).unwrap();
    for e in [
        rejected(0, crc(0), Some(now)),        // current: kept
        rejected(1, Some(12345), Some(now)),   // read while a copy was in progress
        rejected(2, crc(2), Some(then_wrong)), // a wrong board since fixed
        rejected(3, crc(4), Some(now)),        // another frame's event (shuffled)
        rejected(4, None, None),               // an older log: taken as it is
    ] {
        log.log(&e).unwrap();
    }
    drop(log);
    let s = crate::reader::open(&dir).unwrap();
    let stale = stale_outcomes(&s.poses(), &check, std::slice::from_ref(&boards));
    assert_eq!(
        stale,
        [
            (1, Stale::FrameChanged { from_frame: None }),
            (2, Stale::BoardsChanged),
            (
                3,
                Stale::FrameChanged {
                    from_frame: Some(4)
                }
            ),
        ]
    );
    // an outcome recomputed from other inputs is no conflict
    let mut log = SessionAppender::open(&dir).unwrap();
    log.log(&rejected(1, crc(1), Some(now))).unwrap();
    drop(log);
    let s = crate::reader::open(&dir).unwrap();
    assert!(
        s.report.conflicting_poses.is_empty(),
        "{}",
        s.report.summary()
    );
    let stale = stale_outcomes(&s.poses(), &check, &[boards]);
    assert!(stale.iter().all(|(id, _)| *id != 1), "{stale:?}");
}

#[test]
fn the_checksum_is_crc64_xz_at_every_length() {
    // The catalogue's check value of CRC-64/XZ, and the byte-wise table's answer at lengths
    // around the slice-by-16 table's stride: recorded sessions keep verifying.
    assert_eq!(crc64(b"123456789"), 0x995d_c9bb_df19_39fa);
    let bytewise = Crc::<u64>::new(&CRC_64_XZ);
    let bytes: Vec<u8> = (0..100u32).map(|i| (i * 37 % 251) as u8).collect();
    for len in 0..bytes.len() {
        assert_eq!(
            crc64(&bytes[..len]),
            bytewise.checksum(&bytes[..len]),
            "length {len}"
        );
    }
}
