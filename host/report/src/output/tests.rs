use super::*;

/// [`abandon_active`] removes every staging directory of the process: the tests of this module
/// take turns.
static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn run(out: &Path, command: &'static str, content: &str) -> PathBuf {
    let o = OutputDir::claim(out, command, &[]).unwrap();
    std::fs::create_dir_all(o.path().join("sub")).unwrap();
    std::fs::write(o.path().join("sub").join("r.txt"), content).unwrap();
    o.commit().unwrap()
}

#[test]
fn a_users_directory_is_never_written_nor_emptied() {
    let _turn = serial();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("d");
    std::fs::create_dir(&out).unwrap();
    // what a previous demo's output looked like before markers: not enough to own it
    std::fs::write(out.join("summary.json"), b"{}").unwrap();
    std::fs::write(out.join("thesis.tex"), b"keep").unwrap();
    let e = OutputDir::claim(&out, "demo", &[]).unwrap_err();
    assert!(matches!(e, OutputError::NotOurs { .. }), "{e}");
    assert!(e.to_string().contains("thesis.tex"), "{e}");
    assert_eq!(names(&out), ["summary.json", "thesis.tex"]);
    // and nothing was left beside it
    assert_eq!(names(dir.path()), ["d"]);
}

#[test]
fn a_commands_own_output_is_replaced_whole() {
    let _turn = serial();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fit");
    run(&out, "fit", "one");
    run(&out, "fit", "two");
    assert_eq!(
        std::fs::read_to_string(out.join("sub/r.txt")).unwrap(),
        "two"
    );
    assert_eq!(names(dir.path()), ["fit"]);
    // another command's output is not this one's
    let e = OutputDir::claim(&out, "demo", &[]).unwrap_err();
    assert!(matches!(e, OutputError::OtherCommand { .. }), "{e}");
    // a file a user added to an output makes it theirs
    std::fs::write(out.join("notes.txt"), b"mine").unwrap();
    let e = OutputDir::claim(&out, "fit", &[]).unwrap_err();
    assert!(e.to_string().contains("notes.txt"), "{e}");
    // an empty directory is free to take
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    run(&empty, "fit", "x");
    assert!(empty.join(MARKER).is_file());
}

#[test]
fn an_interrupted_run_leaves_the_previous_output_and_its_leftovers_go_next_time() {
    let _turn = serial();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fit");
    run(&out, "fit", "old");
    {
        // dropped without a commit: an error half-way
        let o = OutputDir::claim(&out, "fit", &[]).unwrap();
        std::fs::write(o.path().join("half"), b"x").unwrap();
    }
    assert_eq!(names(dir.path()), ["fit"]);
    assert_eq!(
        std::fs::read_to_string(out.join("sub/r.txt")).unwrap(),
        "old"
    );
    // a killed run's staging directory (nobody holds its lock) is removed by the next run
    let dead = dir.path().join(".fit.ellipso-new-999999999");
    std::fs::create_dir(&dead).unwrap();
    std::fs::write(dead.join("half"), b"x").unwrap();
    std::fs::write(dir.path().join(".fit.ellipso-old-1"), b"").unwrap();
    run(&out, "fit", "new");
    assert_eq!(names(dir.path()), ["fit"]);
}

#[test]
fn a_live_writer_is_not_disturbed() {
    let _turn = serial();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fit");
    let live = dir.path().join(".fit.ellipso-new-1");
    std::fs::create_dir(&live).unwrap();
    let _held = fsops::try_lock(&live).unwrap().unwrap();
    let e = OutputDir::claim(&out, "fit", &[]).unwrap_err();
    assert!(matches!(e, OutputError::Busy { .. }), "{e}");
    assert!(live.is_dir());
    // the refused run took its own staging directory away again
    assert_eq!(names(dir.path()), [".fit.ellipso-new-1"]);
}

#[test]
fn abandoning_removes_every_staging_directory() {
    let _turn = serial();
    let dir = tempfile::tempdir().unwrap();
    let o = OutputDir::claim(&dir.path().join("a"), "fit", &[]).unwrap();
    let staging = o.path().to_path_buf();
    abandon_active();
    assert!(!staging.exists());
    std::mem::forget(o);
}

#[test]
fn published_paths_are_the_users() {
    let _turn = serial();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fit");
    let o = OutputDir::claim(&out, "fit", &[]).unwrap();
    assert_eq!(o.published(&o.path().join("fit.ply")), out.join("fit.ply"));
}

#[test]
fn files_are_claimed_by_format_and_place() {
    let _turn = serial();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let claim = |p: &Path, f: FileFormat| OutputFile::claim(p, "mesh", f, &[], None);
    // the extension is the format's
    let e = claim(&d.join("x.obj"), FileFormat::PLY).unwrap_err();
    assert!(e.to_string().contains(".ply"), "{e}");
    // a directory's name
    let e = claim(Path::new(&format!("{}/out/", d.display())), FileFormat::PLY).unwrap_err();
    assert!(e.to_string().contains("names a directory"), "{e}");
    // a user's file under the name is refused; our own format is replaced
    std::fs::write(d.join("m.ply"), b"my notes").unwrap();
    let e = claim(&d.join("m.ply"), FileFormat::PLY).unwrap_err();
    assert!(e.to_string().contains("not a PLY file"), "{e}");
    std::fs::write(d.join("m.ply"), b"ply\nformat ascii 1.0\n").unwrap();
    let f = claim(&d.join("m.ply"), FileFormat::PLY).unwrap();
    f.write(b"ply\nnew").unwrap();
    assert_eq!(std::fs::read(d.join("m.ply")).unwrap(), b"ply\nnew");
    // the run ends: its claim goes with it
    drop(f);
    // a FIFO is nobody's output
    let fifo = d.join("p.ply");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let e = claim(&fifo, FileFormat::PLY).unwrap_err();
    assert!(e.to_string().contains("not a regular file"), "{e}");
    // a killed writer's temporary file goes with the next claim; a live one's stays
    let dead = d.join(".m.ply.999999999.partial");
    let live = d.join(format!(".m.ply.{}.partial", std::process::id()));
    std::fs::write(&dead, b"x").unwrap();
    std::fs::write(&live, b"x").unwrap();
    claim(&d.join("m.ply"), FileFormat::PLY).unwrap();
    assert!(!dead.exists() && live.exists());
    // an input is never an output
    std::fs::write(d.join("in.json"), b"{}").unwrap();
    let e = OutputFile::claim(
        &d.join("in.json"),
        "x",
        FileFormat::JSON,
        &[&d.join("in.json")],
        None,
    )
    .unwrap_err();
    assert!(matches!(e, OutputError::OverlapsInput { .. }), "{e}");
}

/// Issue 46 item 7: two runs writing one result file at once — the second is refused at its
/// claim, and once the first ends the file is free again.
#[test]
fn a_result_file_is_claimed_by_one_run_at_a_time() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("same.ply");
    let first = OutputFile::claim(&out, "mesh", FileFormat::PLY, &[], None).unwrap();
    // a second claim in this process stands for a second run: flock is per open file
    let e = OutputFile::claim(&out, "mesh", FileFormat::PLY, &[], None).unwrap_err();
    assert!(
        e.to_string()
            .contains("another ellipso run is writing this output now"),
        "{e}"
    );
    first.write(b"ply\nformat ascii 1.0\nend_header\n").unwrap();
    drop(first);
    let again = OutputFile::claim(&out, "mesh", FileFormat::PLY, &[], None).unwrap();
    drop(again);
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left, ["same.ply"], "no claim or temporary file is left");
}

/// Issue 46 (minor): a 250-byte output name failed on the tool's own temporary names.
#[test]
fn long_output_names_get_temporary_names_the_file_system_takes() {
    let dir = tempfile::tempdir().unwrap();
    let long = format!("{}.ply", "n".repeat(246));
    let out = dir.path().join(&long);
    let f = OutputFile::claim(&out, "mesh", FileFormat::PLY, &[], None).unwrap();
    f.write(b"ply\n").unwrap();
    drop(f);
    assert_eq!(std::fs::read(&out).unwrap(), b"ply\n");
    let d = OutputDir::claim(&dir.path().join("d".repeat(250)), "fit", &[]).unwrap();
    std::fs::write(d.path().join("x.json"), b"{}").unwrap();
    d.commit().unwrap();
    let too_long = dir.path().join(format!("{}.ply", "n".repeat(253)));
    let e = OutputFile::claim(&too_long, "mesh", FileFormat::PLY, &[], None).unwrap_err();
    assert!(e.to_string().contains("longer than 255 bytes"), "{e}");
}
