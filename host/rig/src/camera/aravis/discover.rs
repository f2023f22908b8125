//! Camera discovery: the one place ellipso enumerates GigE Vision / USB3 Vision cameras.
//!
//! Contract: [`discover_gige_cameras`] **broadcasts** discovery packets on every network
//! interface. It is for an explicit opt-in CLI flag on a real rig only; tests, examples,
//! benchmarks and default code paths never call it (they open cameras by IP).

/// One camera found by discovery.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DiscoveredCamera {
    /// Aravis device id.
    pub id: String,
    /// Vendor.
    pub vendor: String,
    /// Model.
    pub model: String,
    /// Address (IP for GigE).
    pub address: String,
}

/// **Broadcasts** GigE Vision discovery packets on every network interface (and enumerates USB3
/// Vision devices) and lists what answered.
///
/// Call this only behind an explicit opt-in CLI flag on a real rig. Tests, examples, benchmarks
/// and default code paths must never call it: they open cameras by IP with
/// [`AravisCamera::open`](super::AravisCamera::open).
pub fn discover_gige_cameras() -> Vec<DiscoveredCamera> {
    // libaravis' device list is process-global: serialise our own calls to it
    static DEVICE_LIST: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _guard = DEVICE_LIST.lock().unwrap_or_else(|p| p.into_inner());
    // SAFETY: the list is global state of libaravis; this is the only place ellipso touches it,
    // and the mutex above keeps two of our threads from updating it at once.
    let list = unsafe { aravis::get_device_list() };
    list.into_iter()
        .map(|d| DiscoveredCamera {
            id: d.id.to_string_lossy().into_owned(),
            vendor: d.vendor.to_string_lossy().into_owned(),
            model: d.model.to_string_lossy().into_owned(),
            address: d.address.to_string_lossy().into_owned(),
        })
        .collect()
}
