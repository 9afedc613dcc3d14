//! The overrides: scene values a run replaces, from `collide simulate`'s flags or a
//! manifest's `[sweep]`. Each is declared once below, and everything else follows from
//! that line: its flag (`--NAME`), its manifest key (`sweep.NAME`), its spelling in a
//! configuration's key (`NAME=VALUE`) and its text when a study hands it back to
//! `collide simulate`. Values are raw here; [`crate::run::scene_file`] validates them
//! with the scene.

use serde::Deserialize;
use toml::Spanned;

use crate::run::spec::{MethodChoice, Observe};
use crate::sim::Broadphase;

/// A value written as a number or a word: a time step (0.01 or "auto"), a discard
/// (200.0, "30%" or "auto"). [`crate::run::scene_file`] validates it for its field.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(
    untagged,
    expecting = "expected a number such as 0.01, or a word in quotes such as \"auto\""
)]
pub enum NumberOrWord {
    Number(f64),
    Word(String),
}

/// An override's value as `collide simulate` reads it back.
pub trait OverrideValue {
    fn text(&self) -> String;
}

impl OverrideValue for i64 {
    fn text(&self) -> String {
        self.to_string()
    }
}

impl OverrideValue for u64 {
    fn text(&self) -> String {
        self.to_string()
    }
}

impl OverrideValue for bool {
    fn text(&self) -> String {
        self.to_string()
    }
}

impl OverrideValue for f64 {
    fn text(&self) -> String {
        self.to_string()
    }
}

impl OverrideValue for NumberOrWord {
    fn text(&self) -> String {
        match self {
            NumberOrWord::Number(number) => number.to_string(),
            NumberOrWord::Word(word) => word.clone(),
        }
    }
}

impl OverrideValue for Broadphase {
    fn text(&self) -> String {
        self.name().to_owned()
    }
}

impl OverrideValue for MethodChoice {
    fn text(&self) -> String {
        self.name().to_owned()
    }
}

impl OverrideValue for Observe {
    fn text(&self) -> String {
        self.name().to_owned()
    }
}

/// One list of a manifest's `[sweep]`.
pub struct SweptList {
    /// The override's name (`sweep.KEY`).
    pub key: &'static str,
    /// Where the list starts in the manifest text.
    pub offset: usize,
    pub len: usize,
    /// Sets the override to the list's element i.
    pub set: Setter,
}

/// Sets an override to element i of its swept list.
pub type Setter = Box<dyn Fn(&mut Overrides, usize)>;

/// Declares the overrides: the first group is always part of a configuration's key (`-`
/// when unset), the second joins it only when set (so the keys of manifests written
/// before those could be swept, and their `--resume`, stay as they were). The order is
/// the order of configuration keys and of a sweep's product.
macro_rules! overrides {
    (
        always_keyed: $( $(#[doc = $doc:literal])* #[arg($($arg:tt)*)] $field:ident: $ty:ty, )*
        keyed_when_set: $( $(#[doc = $doc2:literal])* #[arg($($arg2:tt)*)] $field2:ident: $ty2:ty, )*
    ) => {
        /// Values that replace a scene file's: given as flags, or swept by a manifest.
        #[derive(Clone, Debug, Default, PartialEq, clap::Args)]
        pub struct Overrides {
            $( $(#[doc = $doc])* #[arg($($arg)*)] pub $field: Option<$ty>, )*
            $( $(#[doc = $doc2])* #[arg($($arg2)*)] pub $field2: Option<$ty2>, )*
        }

        impl Overrides {
            /// The overrides always named in a configuration's key, in key order.
            pub const ALWAYS_KEYED: &[&str] = &[$(stringify!($field)),*];

            /// Every override by name (its flag without `--`, its `[sweep]` key, its
            /// spelling in configuration keys) with its value as text, `None` where
            /// unset; in declaration order.
            pub fn entries(&self) -> Vec<(&'static str, Option<String>)> {
                vec![
                    $((stringify!($field), self.$field.as_ref().map(OverrideValue::text)),)*
                    $((stringify!($field2), self.$field2.as_ref().map(OverrideValue::text)),)*
                ]
            }
        }

        /// A manifest's `[sweep]`: a list of values for any override, and `zip`.
        #[derive(Default, Deserialize)]
        #[serde(deny_unknown_fields)]
        pub struct SweepLists {
            $( pub $field: Option<Spanned<Vec<$ty>>>, )*
            $( pub $field2: Option<Spanned<Vec<$ty2>>>, )*
            /// Keys whose lists pair up element by element instead of multiplying.
            pub zip: Option<Spanned<Vec<String>>>,
        }

        impl SweepLists {
            /// The lists given, in declaration order.
            pub fn lists(&self) -> Vec<SweptList> {
                let mut lists = Vec::new();
                $( swept_list(&mut lists, stringify!($field), &self.$field, |o, v| o.$field = Some(v)); )*
                $( swept_list(&mut lists, stringify!($field2), &self.$field2, |o, v| o.$field2 = Some(v)); )*
                lists
            }
        }
    };
}

overrides! {
    always_keyed:
    /// Number of disks (random scenes).
    #[arg(long, allow_hyphen_values = true)]
    n: i64,
    /// Area fraction of disks (random scenes; the box becomes square).
    #[arg(long, allow_hyphen_values = true)]
    packing: f64,
    /// Time step, or "auto".
    #[arg(long, value_parser = parse_dt, allow_hyphen_values = true)]
    dt: NumberOrWord,
    /// Number of steps.
    #[arg(long, allow_hyphen_values = true)]
    steps: i64,
    /// Seed of the random initial state.
    #[arg(long, value_parser = parse_seed, allow_negative_numbers = true)]
    seed: u64,
    /// Broad phase: grid (default) or allpairs (the seed's O(N²) search).
    #[arg(long, value_parser = parse_broadphase)]
    broadphase: Broadphase,
    keyed_when_set:
    /// Method: step (time steps of dt, the default), event (the exact event-driven
    /// reference; serial backend only) or auto (the cheaper one within the scene's
    /// missed_tolerance; serial backend only).
    #[arg(long, value_parser = parse_method)]
    method: MethodChoice,
    /// What to measure besides time: timing (default) or accuracy (also the step
    /// method's exact missed-collision count, outside `wall_s`; serial backend only).
    #[arg(long, value_parser = parse_observe)]
    observe: Observe,
    /// TC model time of the event method's inelastic-collapse guard (0 turns it off;
    /// default 1e-4 · r_min / v_rms).
    #[arg(long, allow_hyphen_values = true)]
    tc: f64,
    /// Draw the whole box offscreen after every step, as `collide view` draws it (800 ×
    /// 800 pixels, no window), timed apart from the stepping loop: the result gains
    /// `draw_s` and `fps_with_drawing`. `--draw` alone means true (`--draw=false` sets
    /// it false); serial and rayon backends only.
    #[arg(long, num_args = 0..=1, default_missing_value = "true", require_equals = true)]
    draw: bool,
    /// How much of the run to drop before averaging its observables: a simulated time
    /// (200), a share of the run ("30%"), or "auto" (the default: MSER-5 finds the end of
    /// the transient).
    #[arg(long, value_parser = parse_discard, allow_hyphen_values = true)]
    discard: NumberOrWord,
}

/// Adds the list `values` of the override `key` (if given) to `lists`.
fn swept_list<T: Clone + 'static>(
    lists: &mut Vec<SweptList>,
    key: &'static str,
    values: &Option<Spanned<Vec<T>>>,
    set: fn(&mut Overrides, T),
) {
    if let Some(values) = values {
        let owned = values.get_ref().clone();
        lists.push(SweptList {
            key,
            offset: values.span().start,
            len: owned.len(),
            set: Box::new(move |o: &mut Overrides, i: usize| set(o, owned[i].clone())),
        });
    }
}

fn parse_dt(text: &str) -> Result<NumberOrWord, String> {
    if text == "auto" {
        return Ok(NumberOrWord::Word(text.to_owned()));
    }
    text.parse::<f64>()
        .map(NumberOrWord::Number)
        .map_err(|_| format!("expected a number or \"auto\", got \"{text}\""))
}

/// A number, else a word that the scene's validation judges (naming the flag).
fn parse_discard(text: &str) -> Result<NumberOrWord, String> {
    Ok(text.parse::<f64>().map_or_else(
        |_| NumberOrWord::Word(text.to_owned()),
        NumberOrWord::Number,
    ))
}

fn parse_seed(text: &str) -> Result<u64, String> {
    text.parse::<u64>().map_err(|_| {
        format!(
            "expected a whole number from 0 to {}, got \"{text}\"",
            u64::MAX
        )
    })
}

fn parse_broadphase(text: &str) -> Result<Broadphase, String> {
    match text {
        "grid" => Ok(Broadphase::Grid),
        "allpairs" => Ok(Broadphase::AllPairs),
        _ => Err(format!("expected grid or allpairs, got \"{text}\"")),
    }
}

fn parse_method(text: &str) -> Result<MethodChoice, String> {
    text.parse()
}

fn parse_observe(text: &str) -> Result<Observe, String> {
    match text {
        "timing" => Ok(Observe::Timing),
        "accuracy" => Ok(Observe::Accuracy),
        _ => Err(format!("expected timing or accuracy, got \"{text}\"")),
    }
}
