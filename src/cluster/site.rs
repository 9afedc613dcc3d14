//! A site: where a study's MPI runs go (scheduler, launcher, cores per node, nodes,
//! partition, account, time limit, extra options, environment), read once from
//! `systems/NAME.toml` into a validated [`Site`]; `local` (this host, `mpirun`, no
//! scheduler) is built in, and `--launcher "WORDS"` maps onto a site of its own.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use crate::cluster::network::{Band, Network, RawNetwork, Source, assumed_band};
use crate::run::scene_file::line_of;
use crate::system::input::{MAX_TEXT_BYTES, read_text};

/// The name of the built-in site: this host, no scheduler, `mpirun`.
pub const LOCAL: &str = "local";

/// The folder `--system NAME` looks in (relative to the working directory).
pub const SYSTEMS_DIR: &str = "systems";

/// Who allocates nodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scheduler {
    /// None: ranks start at once on this host (or a host file's, through the launcher).
    None,
    Slurm,
    Pbs,
    Flux,
}

impl Scheduler {
    const ALL: [Scheduler; 4] = [
        Scheduler::None,
        Scheduler::Slurm,
        Scheduler::Pbs,
        Scheduler::Flux,
    ];

    /// The name a site file writes.
    pub fn name(self) -> &'static str {
        match self {
            Scheduler::None => "none",
            Scheduler::Slurm => "slurm",
            Scheduler::Pbs => "pbs",
            Scheduler::Flux => "flux",
        }
    }

    /// Whether runs are submitted as batch jobs rather than started here.
    pub fn is_batch(self) -> bool {
        self != Scheduler::None
    }
}

/// Which program starts the ranks; each takes its own flags ([`crate::cluster::render`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Launcher {
    /// OpenMPI's `mpirun`.
    Mpirun,
    /// The MPI standard's `mpiexec` (MPICH's Hydra flags beyond `-n`).
    Mpiexec,
    /// Slurm's `srun`.
    Srun,
    /// `flux run`.
    Flux,
}

impl Launcher {
    const ALL: [Launcher; 4] = [
        Launcher::Mpirun,
        Launcher::Mpiexec,
        Launcher::Srun,
        Launcher::Flux,
    ];

    /// The name a site file writes, which is also the command run.
    pub fn name(self) -> &'static str {
        match self {
            Launcher::Mpirun => "mpirun",
            Launcher::Mpiexec => "mpiexec",
            Launcher::Srun => "srun",
            Launcher::Flux => "flux run",
        }
    }

    /// The only scheduler it works under, if it needs one.
    fn needs(self) -> Option<Scheduler> {
        match self {
            Launcher::Srun => Some(Scheduler::Slurm),
            Launcher::Flux => Some(Scheduler::Flux),
            Launcher::Mpirun | Launcher::Mpiexec => None,
        }
    }
}

/// Whether ranks are pinned to their cores.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bind {
    /// Each rank to its own cores (its threads' worth): the default.
    Cores,
    /// Not pinned: where the nodes declare cores the host lacks (emulated nodes), the
    /// launcher cannot pin to them.
    None,
}

impl Bind {
    const ALL: [Bind; 2] = [Bind::Cores, Bind::None];

    /// The name a site file writes.
    pub fn name(self) -> &'static str {
        match self {
            Bind::Cores => "cores",
            Bind::None => "none",
        }
    }
}

/// A validated site.
#[derive(Clone, Debug, PartialEq)]
pub struct Site {
    /// `local`, the file's stem, or `--launcher` for a site made from that flag.
    pub name: String,
    pub scheduler: Scheduler,
    pub launcher: Launcher,
    /// The launcher's command words (`mpirun`, `/opt/mpich/bin/mpiexec`, `flux run`).
    pub command: Vec<String>,
    pub cores_per_node: usize,
    pub bind: Bind,
    /// The most nodes a placement may ask for.
    pub max_nodes: usize,
    pub partition: Option<String>,
    pub account: Option<String>,
    /// The scheduler's wall-clock limit per job, as it writes it (`HH:MM:SS`).
    pub time_limit: Option<String>,
    /// Options for the scheduler's job script header, e.g. `--exclusive`.
    pub scheduler_args: Vec<String>,
    /// Options for the launcher, before the placement's own, e.g. `--mpi=pmix`.
    pub launcher_args: Vec<String>,
    /// Variables set for every rank.
    pub env: BTreeMap<String, String>,
    /// The network between its nodes, measured or assumed (`[network]`), if given.
    pub network: Option<Network>,
}

impl Site {
    /// The built-in site: this host's usable CPUs on one node, `mpirun`, no scheduler.
    pub fn local() -> Site {
        Site {
            name: LOCAL.to_owned(),
            scheduler: Scheduler::None,
            launcher: Launcher::Mpirun,
            command: vec![Launcher::Mpirun.name().to_owned()],
            cores_per_node: crate::system::machine::usable_cpus(),
            bind: Bind::Cores,
            max_nodes: 1,
            partition: None,
            account: None,
            time_limit: None,
            scheduler_args: Vec::new(),
            launcher_args: Vec::new(),
            env: BTreeMap::new(),
            network: None,
        }
    }

    /// The site that `--launcher "WORDS"` means: [`Site::local`] with its first word as
    /// the command (the launcher's kind told by that program's file name: `srun`,
    /// `flux`, `mpirun`/`orterun`; any other program is taken as an `mpiexec`, which
    /// receives `-n RANKS` only) and the other words as launcher options.
    pub fn from_launcher(words: &str) -> Result<Site, String> {
        let mut words = words.split_whitespace().map(str::to_owned);
        let program = words.next().ok_or(
            "the MPI launcher command is empty; give one, e.g. --launcher mpirun".to_owned(),
        )?;
        let stem = Path::new(&program)
            .file_name()
            .map_or_else(String::new, |name| name.to_string_lossy().into_owned());
        let mut rest: Vec<String> = words.collect();
        let (launcher, scheduler, command) = match stem.as_str() {
            "mpirun" | "orterun" => (Launcher::Mpirun, Scheduler::None, vec![program]),
            "srun" => (Launcher::Srun, Scheduler::Slurm, vec![program]),
            "flux" if rest.first().is_some_and(|w| w == "run") => {
                rest.remove(0);
                (Launcher::Flux, Scheduler::Flux, vec![program, "run".into()])
            }
            _ => (Launcher::Mpiexec, Scheduler::None, vec![program]),
        };
        Ok(Site {
            name: "--launcher".to_owned(),
            // srun and flux run start ranks inside an allocation the user already holds.
            scheduler,
            launcher,
            command,
            launcher_args: rest,
            ..Site::local()
        })
    }

    /// The file `--system` names: none for `local`, a path to a TOML file (it holds a
    /// `/` or ends in `.toml`), or `systems/NAME.toml`.
    pub fn file_of(name_or_path: &str) -> Option<PathBuf> {
        match name_or_path {
            LOCAL => None,
            _ if name_or_path.contains('/') || name_or_path.ends_with(".toml") => {
                Some(PathBuf::from(name_or_path))
            }
            _ => Some(Path::new(SYSTEMS_DIR).join(format!("{name_or_path}.toml"))),
        }
    }

    /// The site `--system` names: `local`, a path to a TOML file (it holds a `/` or ends
    /// in `.toml`), or NAME for `systems/NAME.toml`.
    pub fn find(name_or_path: &str) -> anyhow::Result<Site> {
        let Some(path) = Site::file_of(name_or_path) else {
            return Ok(Site::local());
        };
        let text = read_text(&path, MAX_TEXT_BYTES).map_err(|reason| {
            anyhow::anyhow!(
                "cannot read the site file {} ({reason}); --system takes `{LOCAL}`, a NAME of \
                 {SYSTEMS_DIR}/NAME.toml, or a path to a site file",
                path.display()
            )
        })?;
        Ok(parse(&path, &text)?)
    }

    /// The network a prediction assumes on this site: its `[network]`, else an assumed
    /// InfiniBand-class band that says this site has none.
    pub fn network_band(&self) -> Band {
        match &self.network {
            Some(network) => network.band(),
            None => {
                let mut band = assumed_band();
                band.label = format!("{} (site `{}` has no [network])", band.label, self.name);
                band
            }
        }
    }

    /// Whether a run started by this site's launcher is itself a batch job.
    pub fn is_batch(&self) -> bool {
        self.scheduler.is_batch() && self.name != "--launcher"
    }
}

/// A site file's error: where (file:line) and what, with the fix.
#[derive(Debug, thiserror::Error)]
#[error("{location}: {message}")]
pub struct SiteError {
    pub location: String,
    pub message: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSite {
    scheduler: Spanned<String>,
    launcher: Option<Spanned<String>>,
    /// The launcher's path when it is not on the PATH under its own name.
    launcher_path: Option<String>,
    cores_per_node: Spanned<i64>,
    bind: Option<Spanned<String>>,
    max_nodes: Option<Spanned<i64>>,
    partition: Option<String>,
    account: Option<String>,
    time_limit: Option<Spanned<String>>,
    #[serde(default)]
    scheduler_args: Vec<String>,
    #[serde(default)]
    launcher_args: Vec<String>,
    #[serde(default)]
    env: BTreeMap<String, Spanned<String>>,
    network: Option<RawNetwork>,
}

/// The keys a site file takes, for the error that names an unknown one.
const KEYS: &str = "scheduler, launcher, launcher_path, cores_per_node, bind, max_nodes, \
                    partition, account, time_limit, scheduler_args, launcher_args, [env], [network]";

/// Validates a site file's text; `path` names it in errors and gives the site its name.
pub fn parse(path: &Path, text: &str) -> Result<Site, SiteError> {
    let file = SiteText { path, text };
    let raw: RawSite = toml::from_str(text).map_err(|err| {
        file.invalid(
            err.span().map_or(0, |span| span.start),
            format!(
                "{}; a site file takes {KEYS} (docs/clusters.md)",
                err.message().trim_end()
            ),
        )
    })?;
    let scheduler = file.choice(
        &Scheduler::ALL,
        Scheduler::name,
        &raw.scheduler,
        "scheduler",
    )?;
    let launcher = file.launcher(&raw, scheduler)?;
    let cores_per_node = file.positive(&raw.cores_per_node, "cores_per_node")?;
    let bind = match &raw.bind {
        None => Bind::Cores,
        Some(bind) => file.choice(&Bind::ALL, Bind::name, bind, "bind")?,
    };
    let max_nodes = match &raw.max_nodes {
        Some(value) => file.positive(value, "max_nodes")?,
        None => 1,
    };
    file.check_time_limit(raw.time_limit.as_ref())?;
    file.check_env(&raw.env)?;
    let network = raw
        .network
        .as_ref()
        .map(|network| file.network(network))
        .transpose()?;
    let mut command: Vec<String> = launcher.name().split(' ').map(str::to_owned).collect();
    if let Some(program) = raw.launcher_path {
        command[0] = program;
    }
    Ok(Site {
        name: path
            .file_stem()
            .map_or_else(|| "site".into(), |s| s.to_string_lossy().into_owned()),
        scheduler,
        launcher,
        command,
        cores_per_node,
        bind,
        max_nodes,
        partition: raw.partition,
        account: raw.account,
        time_limit: raw.time_limit.map(Spanned::into_inner),
        scheduler_args: raw.scheduler_args,
        launcher_args: raw.launcher_args,
        env: raw
            .env
            .into_iter()
            .map(|(key, value)| (key, value.into_inner()))
            .collect(),
        network,
    })
}

/// A site file's text and where it came from: what its errors point into.
struct SiteText<'a> {
    path: &'a Path,
    text: &'a str,
}

impl SiteText<'_> {
    /// An error at byte `offset` of the file, located by line.
    fn invalid(&self, offset: usize, message: String) -> SiteError {
        SiteError {
            location: format!("{}:{}", self.path.display(), line_of(self.text, offset)),
            message,
        }
    }

    /// The item of `all` that `value` names, else an error at it listing the names.
    fn choice<T: Copy>(
        &self,
        all: &[T],
        name: fn(T) -> &'static str,
        value: &Spanned<String>,
        key: &str,
    ) -> Result<T, SiteError> {
        one_of(all, name, value.get_ref()).map_err(|names| {
            self.invalid(
                value.span().start,
                format!("`{key}` is {:?}; give one of {names}", value.get_ref()),
            )
        })
    }

    /// The launcher the site names (else its scheduler's own), if it can start ranks
    /// under that scheduler.
    fn launcher(&self, raw: &RawSite, scheduler: Scheduler) -> Result<Launcher, SiteError> {
        let launcher = match &raw.launcher {
            None => match scheduler {
                Scheduler::Slurm => Launcher::Srun,
                Scheduler::Flux => Launcher::Flux,
                Scheduler::None | Scheduler::Pbs => Launcher::Mpirun,
            },
            Some(launcher) => self.choice(&Launcher::ALL, Launcher::name, launcher, "launcher")?,
        };
        match launcher.needs().filter(|&needed| needed != scheduler) {
            None => Ok(launcher),
            Some(needed) => Err(self.invalid(
                raw.launcher.as_ref().map_or(0, |l| l.span().start),
                format!(
                    "`launcher = \"{}\"` starts ranks only under `scheduler = \"{}\"`, and this \
                     site says \"{}\"; change one of them (`mpirun` and `mpiexec` work under any)",
                    launcher.name(),
                    needed.name(),
                    scheduler.name()
                ),
            )),
        }
    }

    /// A count of at least 1.
    fn positive(&self, value: &Spanned<i64>, key: &str) -> Result<usize, SiteError> {
        usize::try_from(*value.get_ref())
            .ok()
            .filter(|&count| count >= 1)
            .ok_or_else(|| {
                self.invalid(
                    value.span().start,
                    format!(
                        "`{key}` is {}; give a whole number of at least 1",
                        value.get_ref()
                    ),
                )
            })
    }

    fn check_time_limit(&self, limit: Option<&Spanned<String>>) -> Result<(), SiteError> {
        match limit {
            Some(limit) if !is_time_limit(limit.get_ref()) => Err(self.invalid(
                limit.span().start,
                format!(
                    "`time_limit` is {:?}; write it as HH:MM:SS, or D-HH:MM:SS for days",
                    limit.get_ref()
                ),
            )),
            _ => Ok(()),
        }
    }

    /// The `[network]` table: a source of `measured` or `assumed`, and figures that are
    /// positive (standard errors: not negative).
    fn network(&self, raw: &RawNetwork) -> Result<Network, SiteError> {
        let source = self.choice(&Source::ALL, Source::name, &raw.source, "network.source")?;
        // A figure must be positive; a standard error (`positive` false) may be 0.
        let figure = |value: &Spanned<f64>, key: &str, positive: bool| {
            let v = *value.get_ref();
            match v.is_finite() && (v > 0.0 || (!positive && v == 0.0)) {
                true => Ok(v),
                false => Err(self.invalid(
                    value.span().start,
                    format!(
                        "`network.{key}` is {v}; give {} number of seconds (e.g. 1.5e-6)",
                        if positive {
                            "a positive"
                        } else {
                            "a non-negative"
                        }
                    ),
                )),
            }
        };
        let optional = |value: &Option<Spanned<f64>>, key: &str, positive: bool| {
            value.as_ref().map(|v| figure(v, key, positive)).transpose()
        };
        Ok(Network {
            source,
            alpha_s: figure(&raw.alpha_s, "alpha_s", true)?,
            beta_s_per_byte: figure(&raw.beta_s_per_byte, "beta_s_per_byte", true)?,
            allreduce_s: optional(&raw.allreduce_s, "allreduce_s", true)?,
            alpha_se_s: optional(&raw.alpha_se_s, "alpha_se_s", false)?.unwrap_or(0.0),
            beta_se_s_per_byte: optional(&raw.beta_se_s_per_byte, "beta_se_s_per_byte", false)?
                .unwrap_or(0.0),
            note: raw.note.clone(),
        })
    }

    /// Variables a job script can export as they are: a shell name, a value without a
    /// newline or a single quote.
    fn check_env(&self, env: &BTreeMap<String, Spanned<String>>) -> Result<(), SiteError> {
        for (key, value) in env {
            let good = !key.is_empty()
                && !key.starts_with(|c: char| c.is_ascii_digit())
                && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
            if !good || value.get_ref().contains(['\n', '\'']) {
                return Err(self.invalid(
                    value.span().start,
                    format!(
                        "`env.{key}`: a variable's name takes letters, digits and `_` (not first \
                         a digit), and its value no newline nor `'`; rename or requote it"
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// The item of `all` whose name is `text`, or the names to choose from.
fn one_of<T: Copy>(all: &[T], name: fn(T) -> &'static str, text: &str) -> Result<T, String> {
    all.iter()
        .copied()
        .find(|&item| name(item) == text)
        .ok_or_else(|| {
            all.iter()
                .map(|&item| format!("\"{}\"", name(item)))
                .collect::<Vec<_>>()
                .join(", ")
        })
}

/// `HH:MM:SS` or `D-HH:MM:SS`, minutes and seconds below 60.
fn is_time_limit(text: &str) -> bool {
    let clock = text.split_once('-').map_or(text, |(days, clock)| {
        if days.is_empty() || !days.chars().all(|c| c.is_ascii_digit()) {
            ""
        } else {
            clock
        }
    });
    let parts: Vec<&str> = clock.split(':').collect();
    parts.len() == 3
        && parts
            .iter()
            .all(|p| !p.is_empty() && p.len() <= 3 && p.chars().all(|c| c.is_ascii_digit()))
        && parts[1].parse::<u32>().is_ok_and(|m| m < 60)
        && parts[2].parse::<u32>().is_ok_and(|s| s < 60)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn site(text: &str) -> Result<Site, String> {
        parse(Path::new("systems/x.toml"), text).map_err(|e| e.to_string())
    }

    #[test]
    fn a_site_file_is_read_into_a_site_and_its_defaults_follow_the_scheduler() {
        let slurm = site(
            "scheduler = \"slurm\"\ncores_per_node = 8\nmax_nodes = 2\npartition = \"debug\"\n\
             time_limit = \"1-00:10:00\"\nlauncher_args = [\"--mpi=pmix\"]\n\
             [env]\nOMPI_MCA_btl = \"self,tcp\"\n",
        )
        .unwrap();
        assert_eq!(slurm.name, "x");
        assert_eq!(slurm.launcher, Launcher::Srun);
        assert_eq!(slurm.command, ["srun"]);
        assert_eq!((slurm.cores_per_node, slurm.max_nodes), (8, 2));
        assert_eq!(slurm.env["OMPI_MCA_btl"], "self,tcp");
        assert!(slurm.is_batch());
        let flux = site("scheduler = \"flux\"\ncores_per_node = 4\n").unwrap();
        assert_eq!(
            (flux.command.join(" "), flux.max_nodes),
            ("flux run".into(), 1)
        );
        let own = site("scheduler = \"none\"\nlauncher = \"mpiexec\"\nlauncher_path = \"/opt/bin/mpiexec\"\ncores_per_node = 4\n").unwrap();
        assert_eq!(own.command, ["/opt/bin/mpiexec"]);
        assert!(!own.is_batch());
    }

    #[test]
    fn site_errors_name_the_file_the_line_the_field_and_the_fix() {
        for (text, says) in [
            (
                "scheduler = \"lsf\"\ncores_per_node = 4\n",
                "systems/x.toml:1: `scheduler` is \"lsf\"; give one of \"none\", \"slurm\", \"pbs\", \"flux\"",
            ),
            (
                "scheduler = \"none\"\nlauncher = \"srun\"\ncores_per_node = 4\n",
                "systems/x.toml:2: `launcher = \"srun\"` starts ranks only under `scheduler = \"slurm\"`",
            ),
            (
                "scheduler = \"slurm\"\ncores_per_node = 0\n",
                "systems/x.toml:2: `cores_per_node` is 0; give a whole number of at least 1",
            ),
            (
                "scheduler = \"slurm\"\ncores_per_node = 4\ntime_limit = \"10 min\"\n",
                "systems/x.toml:3: `time_limit` is \"10 min\"; write it as HH:MM:SS",
            ),
            (
                "scheduler = \"slurm\"\ncores_per_node = 4\nqueue = \"x\"\n",
                "systems/x.toml:3: unknown field `queue`",
            ),
            (
                "scheduler = \"none\"\ncores_per_node = 4\n[network]\nsource = \"guessed\"\nalpha_s = 1e-6\nbeta_s_per_byte = 1e-10\n",
                "systems/x.toml:4: `network.source` is \"guessed\"; give one of \"measured\", \"assumed\"",
            ),
            (
                "scheduler = \"none\"\ncores_per_node = 4\n[network]\nsource = \"assumed\"\nalpha_s = -1e-6\nbeta_s_per_byte = 1e-10\n",
                "systems/x.toml:5: `network.alpha_s` is -0.000001; give a positive number of seconds",
            ),
            (
                "scheduler = \"slurm\"\ncores_per_node = 4\n[env]\n\"A B\" = \"1\"\n",
                "systems/x.toml:4: `env.A B`: a variable's name takes letters",
            ),
        ] {
            let err = site(text).unwrap_err();
            assert!(err.starts_with(says), "{text}\n→ {err}");
        }
    }

    #[test]
    fn the_launcher_flag_maps_onto_a_site_by_its_program() {
        let plain = Site::from_launcher("mpirun --bind-to core").unwrap();
        assert_eq!(
            (plain.launcher, plain.scheduler),
            (Launcher::Mpirun, Scheduler::None)
        );
        assert_eq!(plain.launcher_args, ["--bind-to", "core"]);
        let srun = Site::from_launcher("/usr/bin/srun --mpi=pmix").unwrap();
        assert_eq!(
            (srun.launcher, srun.command.clone()),
            (Launcher::Srun, vec!["/usr/bin/srun".to_owned()])
        );
        // srun from the flag runs inside an allocation already held: not a batch site.
        assert!(!srun.is_batch());
        let flux = Site::from_launcher("flux run -o x").unwrap();
        assert_eq!(
            (flux.command.join(" "), flux.launcher_args.clone()),
            ("flux run".into(), vec!["-o".to_owned(), "x".to_owned()])
        );
        assert_eq!(
            Site::from_launcher("mpiexec.hydra").unwrap().launcher,
            Launcher::Mpiexec
        );
        assert!(Site::from_launcher("  ").is_err());
    }
}
