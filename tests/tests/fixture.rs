//! Data that several topics read, made once per test binary: simulating the default campaign
//! (three angles of attack, three kinds, 50 s runs) costs seconds, and every topic that needs it
//! needs the same campaign.

use std::sync::OnceLock;

use firmware_sim::campaign::Scenario;
use firmware_sim::dataset::Dataset;

/// The default campaign (`Scenario::default()`), the one `./main-job` records and
/// `models/default/` is fitted on.
pub fn default_campaign() -> &'static Dataset {
    static CAMPAIGN: OnceLock<Dataset> = OnceLock::new();
    CAMPAIGN.get_or_init(|| Scenario::default().simulate(&|| {}).expect("the default campaign simulates"))
}
