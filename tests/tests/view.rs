//! `ellipso view` across processes, without a browser: who may talk to it, and what it refuses.
//!
//! - the default bind is loopback, the printed URL carries a 32-hex-digit token;
//! - a request without the token, with a wrong one, or with a foreign `Host` header (DNS
//!   rebinding) gets 403; the right token and Host get the page and the data;
//! - a path that is neither a session nor a fit is one error line naming it.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::process::Command;
use std::time::Duration;

use ellipso_tests::browser::{ChildGuard, spawn_with_url};
use ellipso_tests::ellipso_bin;
use ellipso_tests::fit_fixture::write_fit_dir;

/// One raw HTTP/1.1 GET; returns (status, body).
fn get(addr: &str, path: &str, host: &str) -> (u16, String) {
    raw(addr, &format!("GET {path} HTTP/1.1\r\nHost: {host}\r\n"))
}

/// One raw request: `head` is the request line and headers, each line ending in CRLF.
fn raw(addr: &str, head: &str) -> (u16, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(s, "{head}Connection: close\r\n\r\n").unwrap();
    let mut resp = Vec::new();
    s.read_to_end(&mut resp).unwrap();
    let text = String::from_utf8_lossy(&resp).to_string();
    let status = text[9..12].parse().unwrap();
    let body = text
        .split_once("\r\n\r\n")
        .map(|x| x.1.to_string())
        .unwrap_or_default();
    (status, body)
}

#[test]
fn view_serves_only_with_the_token_and_its_own_host_and_binds_loopback() {
    let tmp = tempfile::tempdir().unwrap();
    let fit = write_fit_dir(&tmp.path().join("fit"));
    let mut cmd = Command::new(ellipso_bin());
    cmd.arg("view").arg(&fit);
    let (child, url) = spawn_with_url(cmd);
    let _child = ChildGuard(child);
    let rest = url.strip_prefix("http://").unwrap();
    let (addr, query) = rest.split_once("/?token=").unwrap();
    assert!(
        addr.starts_with("127.0.0.1:"),
        "default bind must be loopback: {url}"
    );
    assert_eq!(query.len(), 32);
    assert!(query.bytes().all(|b| b.is_ascii_hexdigit()));
    let port = addr.rsplit_once(':').unwrap().1;

    let ok = |path: &str| get(addr, &format!("{path}?token={query}"), addr);
    let (status, page) = ok("/");
    assert_eq!(status, 200);
    assert!(page.contains("data-mode=\"material\""));
    let (status, info) = ok("/api/material/info");
    assert_eq!(status, 200);
    let info: serde_json::Value = serde_json::from_str(&info).unwrap();
    assert_eq!(info["vertices"], 642);
    let invalid = info["flags"].as_array().unwrap().len() - 1;
    assert!(
        info["flags"][invalid]
            .as_str()
            .unwrap()
            .starts_with("Invalid")
    );
    assert_eq!(
        info["flag_counts"][invalid], 1,
        "the wild vertex is marked invalid"
    );
    // the PNG maps' colour ranges: η over the identifiable vertices of the fixture, 1.35–1.75
    let eta = &info["ranges"][0];
    assert!(
        eta[0].as_f64().unwrap() > 1.34 && eta[1].as_f64().unwrap() < 1.76,
        "{eta}"
    );
    assert_eq!(
        get(addr, "/", &format!("localhost:{port}")).0,
        403,
        "no token"
    );
    let (status, why) = get(addr, "/?token=0123456789abcdef0123456789abcdef", addr);
    assert_eq!(status, 403);
    assert!(why.contains("token"), "{why}");
    for path in [
        "/api/material/mesh.bin",
        "/assets/common.js",
        "/api/live/state",
    ] {
        assert_eq!(get(addr, path, addr).0, 403, "{path} without token");
    }
    let (status, why) = get(
        addr,
        &format!("/?token={query}"),
        &format!("evil.example:{port}"),
    );
    assert_eq!(status, 403, "foreign Host with the right token");
    assert!(why.contains("Host"), "{why}");
    assert_eq!(
        get(addr, &format!("/?token={query}"), "127.0.0.1:1").0,
        403,
        "wrong port in Host"
    );
    assert_eq!(
        get(
            addr,
            &format!("/?token={query}"),
            &format!("localhost:{port}")
        )
        .0,
        200
    );
    assert_eq!(
        ok("/api/live/state").0,
        404,
        "live data is not served in material mode"
    );
}

/// Issue 28, case 10: an absolute-form request target naming another server, and a second
/// `Host` header behind a valid one, are refused like a foreign `Host`; under `--bind ::1` the
/// page answers `localhost` as it does under 127.0.0.1.
#[test]
fn view_refuses_a_foreign_authority_and_two_hosts_and_answers_localhost_on_ipv6() {
    let tmp = tempfile::tempdir().unwrap();
    let fit = write_fit_dir(&tmp.path().join("fit"));
    for bind in ["127.0.0.1", "::1"] {
        let mut cmd = Command::new(ellipso_bin());
        cmd.arg("view").arg(&fit).args(["--bind", bind]);
        let (child, url) = spawn_with_url(cmd);
        let _child = ChildGuard(child);
        let rest = url.strip_prefix("http://").unwrap();
        let (addr, token) = rest.split_once("/?token=").unwrap();
        let port = addr.rsplit_once(':').unwrap().1;
        let path = format!("/api/info?token={token}");
        let (status, why) = raw(
            addr,
            &format!("GET http://evil.example{path} HTTP/1.1\r\nHost: {addr}\r\n"),
        );
        assert_eq!(
            status, 403,
            "{bind}: foreign authority in the request target"
        );
        assert!(why.contains("another server"), "{why}");
        let (status, why) = raw(
            addr,
            &format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nHost: evil.example:{port}\r\n"),
        );
        assert_eq!(status, 403, "{bind}: two Host headers");
        assert!(why.contains("more than one Host"), "{why}");
        // its own authority in absolute form is fine, as is localhost on either loopback
        let own = format!("GET http://{addr}{path} HTTP/1.1\r\nHost: {addr}\r\n");
        assert_eq!(raw(addr, &own).0, 200, "{bind}: own absolute form");
        assert_eq!(
            get(addr, &path, &format!("localhost:{port}")).0,
            200,
            "{bind}: localhost"
        );
    }
}

#[test]
fn view_of_a_path_that_is_neither_a_session_nor_a_fit_names_it() {
    let tmp = tempfile::tempdir().unwrap();
    let out = Command::new(ellipso_bin())
        .arg("view")
        .arg(tmp.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("neither a session") && err.contains(&tmp.path().display().to_string()),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}
