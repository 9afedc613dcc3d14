//! A site's network: latency α and inverse bandwidth β (a message of b bytes takes
//! α + b·β, Hockney's model), and the time of a small all-reduce round; measured by
//! `collide calibrate --network` (an MPI ping-pong between 2 ranks, fitted here) or
//! given by hand as a labelled assumption, in the site file's `[network]` table.
//! Leaves out what uses it: the scaling model is `report::prediction`'s.

use serde::{Deserialize, Serialize};

/// Whether the figures were measured or assumed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    Measured,
    Assumed,
}

impl Source {
    pub const ALL: [Source; 2] = [Source::Measured, Source::Assumed];

    /// The name a site file writes.
    pub fn name(self) -> &'static str {
        match self {
            Source::Measured => "measured",
            Source::Assumed => "assumed",
        }
    }
}

/// A validated `[network]` table.
#[derive(Clone, Debug, PartialEq)]
pub struct Network {
    pub source: Source,
    /// Seconds of a message of no bytes (latency α).
    pub alpha_s: f64,
    /// Seconds per byte (β, the inverse of the bandwidth).
    pub beta_s_per_byte: f64,
    /// Seconds of a small all-reduce between 2 ranks (one round), if measured.
    pub allreduce_s: Option<f64>,
    /// Standard errors of α and β (0 where unknown, as for most assumptions).
    pub alpha_se_s: f64,
    pub beta_se_s_per_byte: f64,
    /// How, where and when the figures were obtained, in words.
    pub note: String,
}

/// One end of a band: the figures a message costs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Link {
    pub alpha_s: f64,
    pub beta_s_per_byte: f64,
    /// Seconds of one round of a small all-reduce (its ⌈log₂ P⌉ rounds each cost this).
    pub round_s: f64,
}

/// The network a prediction assumes: a fast and a slow end, and what they are in words.
#[derive(Clone, Debug, PartialEq)]
pub struct Band {
    pub fast: Link,
    pub slow: Link,
    pub label: String,
}

/// Standard errors each side of a measured figure that the band spans.
const BAND_SE: f64 = 2.0;

impl Network {
    /// The band a prediction spans: α and β ± 2 standard errors (never below a tenth of
    /// the figure); an all-reduce round costs the measured 2-rank all-reduce, else α.
    pub fn band(&self) -> Band {
        let at = |sign: f64| {
            let alpha = (self.alpha_s + sign * BAND_SE * self.alpha_se_s).max(0.1 * self.alpha_s);
            let beta = (self.beta_s_per_byte + sign * BAND_SE * self.beta_se_s_per_byte)
                .max(0.1 * self.beta_s_per_byte);
            let round = self
                .allreduce_s
                .map_or(alpha, |s| s * alpha / self.alpha_s.max(f64::MIN_POSITIVE));
            Link {
                alpha_s: alpha,
                beta_s_per_byte: beta,
                round_s: round,
            }
        };
        Band {
            fast: at(-1.0),
            slow: at(1.0),
            label: format!(
                "{} network: α {} µs, β {} ns/B ({:.2} GB/s){}{}",
                self.source.name(),
                sig(self.alpha_s * 1e6),
                sig(self.beta_s_per_byte * 1e9),
                1e-9 / self.beta_s_per_byte,
                self.allreduce_s.map_or_else(String::new, |s| format!(
                    ", 2-rank all-reduce {} µs",
                    sig(s * 1e6)
                )),
                match self.note.is_empty() {
                    true => String::new(),
                    false => format!(" ({})", self.note),
                }
            ),
        }
    }
}

/// The band assumed where a site has no `[network]`: an InfiniBand-class network, α
/// 1–3 µs and β 0.04–0.1 ns/B (10–25 GB/s).
pub fn assumed_band() -> Band {
    Band {
        fast: Link {
            alpha_s: 1e-6,
            beta_s_per_byte: 4e-11,
            round_s: 1e-6,
        },
        slow: Link {
            alpha_s: 3e-6,
            beta_s_per_byte: 1e-10,
            round_s: 3e-6,
        },
        label: "assumed network (none measured): InfiniBand-class, α 1–3 µs, β 0.04–0.1 ns/B \
                (10–25 GB/s)"
            .to_owned(),
    }
}

/// Three significant digits, for the words of a label.
fn sig(value: f64) -> String {
    format!("{value:.3}")
        .trim_end_matches('0')
        .trim_end_matches('.')
        .to_owned()
}

/// One size of the ping-pong: the bytes of a message and the one-way seconds it took
/// (half the mean round trip).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    pub bytes: f64,
    pub seconds: f64,
}

/// What the two ranks measured: the ping-pong's sizes and a small all-reduce.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Measured {
    pub samples: Vec<Sample>,
    pub allreduce_s: f64,
}

/// Message sizes of the ping-pong: 8 B to 1 MiB, a factor 8 apart.
pub const SIZES: [usize; 7] = [8, 64, 512, 4096, 32_768, 262_144, 1_048_576];

/// Fits t = α + b·β to the samples by least squares on relative errors (weights 1/t²,
/// so small messages set α and large ones β), with the standard errors of both. `None`
/// with fewer than 3 samples, or sizes all equal.
pub fn fit(measured: &Measured, note: String) -> Option<Network> {
    let points = &measured.samples;
    if points.len() < 3 {
        return None;
    }
    // Weighted normal equations of t = α + β·b.
    let (mut sw, mut sb, mut sbb, mut st, mut sbt) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for p in points {
        let w = 1.0 / (p.seconds * p.seconds);
        sw += w;
        sb += w * p.bytes;
        sbb += w * p.bytes * p.bytes;
        st += w * p.seconds;
        sbt += w * p.bytes * p.seconds;
    }
    let det = sw * sbb - sb * sb;
    if det <= 0.0 || !det.is_finite() {
        return None;
    }
    let beta = (sw * sbt - sb * st) / det;
    let alpha = (st - beta * sb) / sw;
    // The weighted residuals' variance scales the covariance (sbb, sw)/det.
    let chi2: f64 = points
        .iter()
        .map(|p| ((p.seconds - alpha - beta * p.bytes) / p.seconds).powi(2))
        .sum();
    let variance = chi2 / (points.len() - 2) as f64;
    Some(Network {
        source: Source::Measured,
        // A ping-pong on loopback can fit α a hair below 0: the smallest message's time
        // bounds it from above, and a tenth of that stands in.
        alpha_s: alpha.max(0.1 * points[0].seconds),
        beta_s_per_byte: beta.max(f64::MIN_POSITIVE),
        allreduce_s: Some(measured.allreduce_s),
        alpha_se_s: (variance * sbb / det).sqrt(),
        beta_se_s_per_byte: (variance * sw / det).sqrt(),
        note,
    })
}

/// The `[network]` table of a site file, as TOML lines.
pub fn table(network: &Network) -> String {
    let mut lines = vec![
        "[network]".to_owned(),
        format!("source = \"{}\"", network.source.name()),
        format!("alpha_s = {:e}", network.alpha_s),
        format!("beta_s_per_byte = {:e}", network.beta_s_per_byte),
    ];
    if let Some(seconds) = network.allreduce_s {
        lines.push(format!("allreduce_s = {seconds:e}"));
    }
    lines.push(format!("alpha_se_s = {:e}", network.alpha_se_s));
    lines.push(format!(
        "beta_se_s_per_byte = {:e}",
        network.beta_se_s_per_byte
    ));
    lines.push(format!("note = {:?}", network.note));
    lines.join("\n") + "\n"
}

/// A site file's text with its `[network]` table (from its header to the next table or
/// the end) replaced by `table`, or `table` appended.
pub fn with_table(text: &str, table: &str) -> String {
    let mut kept = Vec::new();
    let mut inside = false;
    for line in text.lines() {
        let header = line.trim_start().starts_with('[');
        if header {
            inside = line.trim() == "[network]";
        }
        if !inside {
            kept.push(line);
        }
    }
    while kept.last().is_some_and(|line| line.trim().is_empty()) {
        kept.pop();
    }
    let mut out = kept.join("\n");
    if !out.is_empty() {
        out.push_str("\n\n");
    }
    out + table
}

/// A `[network]` table as a site file writes it, before validation.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawNetwork {
    pub source: toml::Spanned<String>,
    pub alpha_s: toml::Spanned<f64>,
    pub beta_s_per_byte: toml::Spanned<f64>,
    pub allreduce_s: Option<toml::Spanned<f64>>,
    pub alpha_se_s: Option<toml::Spanned<f64>>,
    pub beta_se_s_per_byte: Option<toml::Spanned<f64>>,
    #[serde(default)]
    pub note: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn measured(alpha: f64, beta: f64) -> Measured {
        Measured {
            samples: SIZES
                .iter()
                .map(|&b| Sample {
                    bytes: b as f64,
                    seconds: alpha + beta * b as f64,
                })
                .collect(),
            allreduce_s: 2.0 * alpha,
        }
    }

    #[test]
    fn a_ping_pong_on_a_hockney_network_fits_its_latency_and_bandwidth() {
        let network = fit(&measured(2e-6, 1e-10), "test".into()).unwrap();
        assert!((network.alpha_s / 2e-6 - 1.0).abs() < 1e-9);
        assert!((network.beta_s_per_byte / 1e-10 - 1.0).abs() < 1e-9);
        assert!(network.alpha_se_s < 1e-15 && network.beta_se_s_per_byte < 1e-20);
        let band = network.band();
        // Exact samples: the fit's standard errors are rounding, and the band is a point.
        assert!((band.fast.alpha_s / band.slow.alpha_s - 1.0).abs() < 1e-6);
        assert!((band.fast.beta_s_per_byte / band.slow.beta_s_per_byte - 1.0).abs() < 1e-6);
        // The all-reduce round is the measured one.
        assert!((band.fast.round_s / 4e-6 - 1.0).abs() < 1e-6);
        assert!(
            band.label
                .starts_with("measured network: α 2 µs, β 0.1 ns/B (10.00 GB/s)")
        );
    }

    #[test]
    fn noise_widens_the_band_and_too_few_sizes_fit_nothing() {
        let mut noisy = measured(2e-6, 1e-10);
        for (i, sample) in noisy.samples.iter_mut().enumerate() {
            sample.seconds *= if i % 2 == 0 { 1.1 } else { 0.9 };
        }
        let band = fit(&noisy, String::new()).unwrap().band();
        assert!(band.fast.alpha_s < band.slow.alpha_s);
        assert!(band.fast.beta_s_per_byte < band.slow.beta_s_per_byte);
        noisy.samples.truncate(2);
        assert!(fit(&noisy, String::new()).is_none());
    }

    #[test]
    fn the_network_table_replaces_the_old_one_and_keeps_the_rest() {
        let text = "scheduler = \"none\"\ncores_per_node = 2\n\n[network]\nsource = \"assumed\"\n\
                    alpha_s = 1e-6\n\n[env]\nA = \"1\"\n";
        let table = "[network]\nsource = \"measured\"\n";
        let out = with_table(text, table);
        assert_eq!(
            out,
            "scheduler = \"none\"\ncores_per_node = 2\n\n[env]\nA = \"1\"\n\n[network]\nsource = \"measured\"\n"
        );
        assert_eq!(with_table(&out, table), out);
        let network = fit(&measured(2e-6, 1e-10), "ping-pong".into()).unwrap();
        let written = table_round_trip(&network);
        assert_eq!(written, network);
    }

    /// The network a site file holding `table(network)` reads back.
    fn table_round_trip(network: &Network) -> Network {
        let text = format!(
            "scheduler = \"none\"\ncores_per_node = 2\n{}",
            table(network)
        );
        crate::cluster::site::parse(std::path::Path::new("systems/x.toml"), &text)
            .unwrap()
            .network
            .unwrap()
    }
}
