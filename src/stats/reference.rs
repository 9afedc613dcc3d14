//! Reference values of the hard-disk compressibility factor Z = βP/ρ to compare a run
//! with: an equation of state where one is accurate, tabulated high-precision values
//! (each with its N and box) where none is, and the comparison as a z-score with both
//! error bars. Sources in `docs/accuracy.md`.

/// A reference Z with its standard uncertainty and where it comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reference {
    pub z: f64,
    /// One standard uncertainty of the reference itself.
    pub se: f64,
    /// The source and the system it holds for, in words.
    pub source: &'static str,
}

/// Below this packing Henderson's equation is within 0.7% (it is 1.3% above Luding's at 0.6).
pub const HENDERSON_LIMIT: f64 = 0.5;
/// Up to this packing Luding's equation is within about 0.1%.
pub const LUDING_LIMIT: f64 = 0.6;
/// Luding's relative uncertainty up to [`LUDING_LIMIT`].
const LUDING_RELATIVE_SE: f64 = 1e-3;

/// Tabulated values [η, Z, SE of Z, source]: the only references above [`LUDING_LIMIT`],
/// where the equation of state depends on N and the box (the liquid–hexatic region).
const TABLE: [(f64, f64, f64, &str); 3] = [
    (
        0.698,
        10.31907,
        0.00005,
        "βPσ² = 9.170780 ± 0.000045, N = 256², periodic square box (Anderson et al. 2013, HOOMD-blue's validation value)",
    ),
    (
        0.718,
        9.900,
        0.004,
        "βPσ² = 9.0507 ± 0.0040, N = 870, periodic square box (Li et al. 2022)",
    ),
    (
        0.720,
        10.0658,
        0.0003,
        "βPσ² = 9.22765 ± 0.00025, N = 1024², periodic square box (Bernard & Krauth 2011)",
    ),
];

/// A tabulated packing matches when within this of the run's.
const TABLE_TOLERANCE: f64 = 5e-4;

/// Henderson's Z = (1 + η²/8)/(1 − η)².
pub fn henderson(packing: f64) -> f64 {
    (1.0 + packing * packing / 8.0) / (1.0 - packing).powi(2)
}

/// Luding's Z = (1 + η²/8 − η⁴/10)/(1 − η)² (Phys. Rev. E 63, 042201 (2001)).
pub fn luding(packing: f64) -> f64 {
    (1.0 + packing * packing / 8.0 - packing.powi(4) / 10.0) / (1.0 - packing).powi(2)
}

/// The reference for a fluid of equal elastic hard disks at `packing` in a periodic
/// box: Henderson below [`HENDERSON_LIMIT`] (its uncertainty its distance from Luding
/// plus Luding's own), Luding up to [`LUDING_LIMIT`], a tabulated value at its packing
/// above; `None` elsewhere.
pub fn hard_disk_z(packing: f64) -> Option<Reference> {
    if packing <= 0.0 {
        return None;
    }
    if packing < HENDERSON_LIMIT {
        let z = henderson(packing);
        let luding = luding(packing);
        return Some(Reference {
            z,
            se: (z - luding).abs() + LUDING_RELATIVE_SE * luding,
            source: "Henderson's equation of state (thermodynamic limit)",
        });
    }
    if packing <= LUDING_LIMIT {
        let z = luding(packing);
        return Some(Reference {
            z,
            se: LUDING_RELATIVE_SE * z,
            source: "Luding's equation of state (thermodynamic limit, ±0.1%)",
        });
    }
    TABLE
        .iter()
        .find(|(eta, ..)| (eta - packing).abs() <= TABLE_TOLERANCE)
        .map(|&(_, z, se, source)| Reference { z, se, source })
}

/// (Z − Z_ref)/√(SE² + SE_ref²): how many combined standard errors apart.
pub fn z_score(z: f64, se: f64, reference: &Reference) -> f64 {
    (z - reference.z) / (se * se + reference.se * reference.se).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_range_has_its_reference() {
        // Henderson is 0.61% above Luding at 0.5 and 1.26% at 0.6.
        assert!((henderson(0.5) / luding(0.5) - 1.0 - 0.0061).abs() < 1e-4);
        assert!((henderson(0.6) / luding(0.6) - 1.0 - 0.0126).abs() < 1e-4);
        let dilute = hard_disk_z(0.3).unwrap();
        assert!(dilute.source.starts_with("Henderson"));
        assert!(hard_disk_z(0.55).unwrap().source.starts_with("Luding"));
        assert_eq!(hard_disk_z(0.698).unwrap().z, 10.31907);
        // Between Luding's range and the table: nothing to compare with.
        assert_eq!(hard_disk_z(0.65), None);
        // βPσ²·π/(4η) = Z for the tabulated values.
        for (eta, z, _, source) in TABLE {
            let value = source
                .split(" = ")
                .nth(1)
                .unwrap()
                .split(' ')
                .next()
                .unwrap();
            let pressure: f64 = value.parse().unwrap();
            let from_pressure = pressure * std::f64::consts::PI / (4.0 * eta);
            assert!(
                (from_pressure / z - 1.0).abs() < 1e-4,
                "{eta}: {from_pressure}"
            );
        }
    }

    #[test]
    fn the_z_score_counts_both_error_bars() {
        let reference = Reference {
            z: 10.0,
            se: 0.03,
            source: "",
        };
        assert!((z_score(10.2, 0.04, &reference) - 4.0).abs() < 1e-12);
    }
}
