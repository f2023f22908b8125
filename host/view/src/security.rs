//! Who may talk to `ellipso view`: a per-run secret token and a Host-header allow-list.
//!
//! Contract:
//! - [`Token::generate`] draws 128 bits from the thread CSPRNG (ChaCha, seeded by the OS) and
//!   writes them as 32 hex digits; the page's URL carries it as `?token=…`, as Jupyter does.
//!   Every request must present it (query `token`, or header `Authorization: Bearer …`);
//!   the comparison takes the same time wherever the first difference is.
//! - [`HostPolicy`] refuses a request whose `Host` header does not name the bound address.
//!   This is the defence against DNS rebinding: a page on a hostile site that rebinds its own
//!   name to 127.0.0.1 still sends `Host: hostile.example`, which is refused before the token is
//!   even looked at. Accepted: the bound IP literal with the bound port; `localhost` when bound
//!   to loopback; any IP literal when bound to an unspecified address (`0.0.0.0`, `::`), since an
//!   IP literal cannot be rebound; and names given with `--allow-host`.
//! - The default bind is loopback ([`DEFAULT_BIND`]); anything else is the user's explicit
//!   `--bind`.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};

/// The address `ellipso view` binds to unless told otherwise: loopback, a free port.
pub const DEFAULT_BIND: SocketAddr = SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), 0);

/// The per-run secret.
#[derive(Clone, PartialEq, Eq)]
pub struct Token(String);

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Token(…)")
    }
}

impl Token {
    /// 128 random bits as 32 lowercase hex digits.
    pub fn generate() -> Self {
        use rand::Rng;
        let bytes: [u8; 16] = rand::rng().random();
        Self(bytes.iter().map(|b| format!("{b:02x}")).collect())
    }

    /// The token's text.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Whether `candidate` equals the token, in time independent of where they differ.
    pub fn matches(&self, candidate: &str) -> bool {
        let (a, b) = (self.0.as_bytes(), candidate.as_bytes());
        let mut diff = u8::from(a.len() != b.len());
        for (i, x) in a.iter().enumerate() {
            diff |= x ^ b.get(i).copied().unwrap_or(0);
        }
        diff == 0
    }
}

/// Which `Host` headers are accepted.
#[derive(Clone, Debug)]
pub struct HostPolicy {
    bound: SocketAddr,
    extra_names: Vec<String>,
}

impl HostPolicy {
    /// For a server listening on `bound` (the real port, after binding), accepting also the
    /// host names in `extra_names` (`--allow-host`).
    pub fn new(bound: SocketAddr, extra_names: Vec<String>) -> Self {
        let extra_names = extra_names.into_iter().map(|n| n.to_lowercase()).collect();
        Self { bound, extra_names }
    }

    /// Whether a request with this `Host` header value may proceed.
    pub fn allows(&self, host_header: &str) -> bool {
        let Some((host, port)) = split_host_port(host_header) else {
            return false;
        };
        // HTTP/1.1 clients always send the port for a non-default one; a missing port would
        // mean 80, which this server never is unless bound there.
        if port.unwrap_or(80) != self.bound.port() {
            return false;
        }
        let host = host.to_lowercase();
        if let Ok(ip) = host.parse::<IpAddr>() {
            return ip == self.bound.ip() || self.bound.ip().is_unspecified();
        }
        (host == "localhost" && self.bound.ip().is_loopback()) || self.extra_names.contains(&host)
    }
}

/// `host[:port]` or `[v6]:port` → (host without brackets, port).
fn split_host_port(value: &str) -> Option<(&str, Option<u16>)> {
    let value = value.trim();
    if let Some(rest) = value.strip_prefix('[') {
        let (host, after) = rest.split_once(']')?;
        return match after.strip_prefix(':') {
            Some(p) => Some((host, Some(p.parse().ok()?))),
            None if after.is_empty() => Some((host, None)),
            None => None,
        };
    }
    match value.rsplit_once(':') {
        // a bare IPv6 literal without brackets is not a valid Host header
        Some((h, _)) if h.contains(':') => None,
        Some((h, p)) => Some((h, Some(p.parse().ok()?))),
        None if value.is_empty() => None,
        None => Some((value, None)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_are_random_hex_and_compare_exactly() {
        let (a, b) = (Token::generate(), Token::generate());
        assert_ne!(a, b);
        assert_eq!(a.as_str().len(), 32);
        assert!(a.as_str().bytes().all(|c| c.is_ascii_hexdigit()));
        assert!(a.matches(a.as_str()));
        assert!(!a.matches(b.as_str()));
        assert!(!a.matches(""));
        assert!(!a.matches(&a.as_str()[..31]));
        assert!(!a.matches(&format!("{}0", a.as_str())));
        assert!(
            !format!("{a:?}").contains(a.as_str()),
            "Debug must not leak it"
        );
    }

    #[test]
    fn loopback_accepts_its_own_address_and_localhost_only() {
        let p = HostPolicy::new("127.0.0.1:8123".parse().unwrap(), vec![]);
        assert!(p.allows("127.0.0.1:8123"));
        assert!(p.allows("localhost:8123"));
        assert!(p.allows("LOCALHOST:8123"));
        for bad in [
            "evil.example:8123",
            "127.0.0.1:8124",
            "127.0.0.2:8123",
            "127.0.0.1",
            "",
            "127.0.0.1:8123:1",
            "[::1]:8123",
            "localhost.evil.example:8123",
        ] {
            assert!(!p.allows(bad), "{bad} must be refused");
        }
    }

    #[test]
    fn unspecified_bind_accepts_ip_literals_and_named_hosts() {
        let p = HostPolicy::new("0.0.0.0:9000".parse().unwrap(), vec!["Rig-Laptop".into()]);
        assert!(p.allows("192.168.1.20:9000"));
        assert!(p.allows("rig-laptop:9000"));
        assert!(!p.allows("localhost:9000"), "not loopback-bound");
        assert!(!p.allows("evil.example:9000"));
        let v6 = HostPolicy::new("[::1]:9000".parse().unwrap(), vec![]);
        assert!(v6.allows("[::1]:9000"));
        assert!(v6.allows("localhost:9000"));
        assert!(!v6.allows("[::2]:9000"));
    }

    #[test]
    fn default_bind_is_loopback() {
        assert!(DEFAULT_BIND.ip().is_loopback());
    }
}
