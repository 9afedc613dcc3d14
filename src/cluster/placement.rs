//! Where one run's ranks and threads go on a site's nodes ([`Layout`]), and whether the
//! site holds them: the nodes it has, ranks spread evenly over the nodes, and ranks ×
//! threads within its cores unless the user insists.

use crate::cluster::site::Site;
use crate::system::machine::allowed_cpu_list;

/// A run's ranks and threads on nodes: `ranks` processes spread evenly over `nodes`,
/// each stepping on `threads` threads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Layout {
    pub nodes: usize,
    pub ranks: usize,
    pub threads: usize,
}

impl Layout {
    /// Ranks on each node.
    pub fn ranks_per_node(self) -> usize {
        self.ranks / self.nodes.max(1)
    }

    /// Whether ranks × threads exceed the cores of its nodes on `site`.
    pub fn oversubscribes(self, site: &Site) -> bool {
        self.ranks * self.threads > self.nodes * site.cores_per_node
    }

    /// `Ok` when `site` can hold this layout; otherwise what is wrong and how to fix it.
    /// `insist` (`oversubscribe = true`, `--oversubscribe`) allows more ranks × threads
    /// than cores.
    pub fn check(self, site: &Site, insist: bool) -> Result<(), String> {
        let Layout {
            nodes,
            ranks,
            threads,
        } = self;
        if nodes == 0 || ranks == 0 || threads == 0 {
            return Err("nodes, ranks and threads are each at least 1".into());
        }
        if nodes > site.max_nodes {
            return Err(format!(
                "{nodes} nodes asked for, and the site `{}` has {} (`max_nodes`); ask for fewer \
                 nodes or raise `max_nodes` in its site file",
                site.name, site.max_nodes
            ));
        }
        if ranks % nodes != 0 {
            return Err(format!(
                "{ranks} ranks do not spread evenly over {nodes} nodes; give a rank count that \
                 is a multiple of the node count"
            ));
        }
        if self.oversubscribes(site) && !insist {
            return Err(format!(
                "{ranks} ranks × {threads} threads need {} cores, and {nodes} node(s) of the \
                 site `{}` have {} ({} per node); use fewer ranks or threads, more nodes, or \
                 insist with `oversubscribe = true` under [backends] (--oversubscribe)",
                ranks * threads,
                site.name,
                nodes * site.cores_per_node,
                site.cores_per_node
            ));
        }
        Ok(())
    }
}

impl std::fmt::Display for Layout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} node(s) × {} rank(s) × {} thread(s)",
            self.nodes,
            self.ranks_per_node(),
            self.threads
        )
    }
}

/// Where one rank of a batch job ran: the line it printed first (`collide-rank: RANK
/// HOST CPUS THREADS`, CPUs as the kernel lists them, e.g. `0-3,8`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RankCpus {
    pub rank: usize,
    pub host: String,
    pub cpus: String,
    pub threads: usize,
}

/// The ranks' lines in a job's error output, in rank order.
pub fn rank_cpus(stderr: &str) -> Vec<RankCpus> {
    let mut ranks: Vec<RankCpus> = stderr
        .lines()
        .filter_map(|line| {
            let words: Vec<&str> = line.strip_prefix("collide-rank: ")?.split(' ').collect();
            let [rank, host, cpus, threads] = words[..] else {
                return None;
            };
            Some(RankCpus {
                rank: rank.parse().ok()?,
                host: host.to_owned(),
                cpus: cpus.to_owned(),
                threads: threads.parse().ok()?,
            })
        })
        .collect();
    // A rank of a batch job reports twice (its job script's line, then its own): the
    // first is kept.
    ranks.sort_by_key(|r| r.rank);
    ranks.dedup_by_key(|r| r.rank);
    ranks
}

/// The line a rank prints first on its error output, which [`rank_cpus`] reads: its
/// rank, host, allowed CPUs (`Cpus_allowed_list`) and threads.
pub fn rank_line(rank: usize, threads: usize) -> String {
    let cpus = allowed_cpu_list().unwrap_or_else(|| "unknown".to_owned());
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
    let host = host.trim();
    format!(
        "collide-rank: {rank} {} {cpus} {threads}",
        if host.is_empty() { "unknown" } else { host }
    )
}

/// The ranks as the records' `rank_cpus` column writes them, in rank order:
/// `HOST:CPUS/THREADS` each, joined by `; ` (e.g. `n1:0/1; n1:1/1`).
pub fn rank_cpus_column(ranks: &[RankCpus]) -> String {
    ranks
        .iter()
        .map(|r| format!("{}:{}/{}", r.host, r.cpus, r.threads))
        .collect::<Vec<_>>()
        .join("; ")
}

/// What is wrong with where the ranks ran: ranks on one host allowed the same CPUs
/// (one warning per host, naming them), or a rank allowed fewer CPUs than it has threads.
pub fn mask_warnings(ranks: &[RankCpus]) -> Vec<String> {
    let sets: Vec<Vec<usize>> = ranks.iter().map(|r| cpu_list(&r.cpus)).collect();
    let mut warnings = Vec::new();
    let mut hosts: Vec<&str> = ranks.iter().map(|r| r.host.as_str()).collect();
    hosts.sort_unstable();
    hosts.dedup();
    for host in hosts {
        let sharing: Vec<String> = (0..ranks.len())
            .filter(|&i| ranks[i].host == host)
            .filter(|&i| {
                (0..ranks.len()).any(|j| {
                    j != i
                        && ranks[j].host == host
                        && sets[i].iter().any(|cpu| sets[j].contains(cpu))
                })
            })
            .map(|i| format!("{} ({})", ranks[i].rank, ranks[i].cpus))
            .collect();
        if !sharing.is_empty() {
            warnings.push(format!(
                "on {host}, ranks {} share CPUs: they take turns rather than run at once",
                sharing.join(", ")
            ));
        }
    }
    for (rank, set) in ranks.iter().zip(&sets) {
        if set.len() < rank.threads {
            warnings.push(format!(
                "rank {} on {} may run on {} CPU(s) ({}) for its {} threads",
                rank.rank,
                rank.host,
                set.len(),
                rank.cpus,
                rank.threads
            ));
        }
    }
    warnings
}

/// The CPUs of a kernel CPU list (`0-3,8`).
fn cpu_list(text: &str) -> Vec<usize> {
    // A part that does not read as a CPU or a range of CPUs adds none.
    text.split(',')
        .filter_map(|part| {
            let (low, high) = part.split_once('-').unwrap_or((part, part));
            match (low.trim().parse::<usize>(), high.trim().parse::<usize>()) {
                (Ok(low), Ok(high)) if high >= low && high - low < 1 << 16 => Some(low..=high),
                _ => None,
            }
        })
        .flatten()
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranks_say_where_they_ran_and_shared_or_scarce_cpus_are_warned_of() {
        let stderr = "collide-rank: 1 n1 2-3 2\nnoise\ncollide-rank: 0 n1 0-1 2\n\
                      collide-rank: 0 n1 0-1 1\n\
                      collide-rank: 2 n2 0-1 2\ncollide-rank: 3 n2 1 2\n";
        let ranks = rank_cpus(stderr);
        let order: Vec<(usize, &str, &str)> = ranks
            .iter()
            .map(|r| (r.rank, r.host.as_str(), r.cpus.as_str()))
            .collect();
        assert_eq!(
            order,
            [
                (0, "n1", "0-1"),
                (1, "n1", "2-3"),
                (2, "n2", "0-1"),
                (3, "n2", "1")
            ]
        );
        assert_eq!(
            mask_warnings(&ranks),
            [
                "on n2, ranks 2 (0-1), 3 (1) share CPUs: they take turns rather than run at once",
                "rank 3 on n2 may run on 1 CPU(s) (1) for its 2 threads"
            ]
        );
        assert!(mask_warnings(&ranks[..2]).is_empty());
        // Rank 0's first line is kept; the record's column lists the ranks in order.
        assert_eq!(rank_cpus_column(&ranks[..2]), "n1:0-1/2; n1:2-3/2");
        assert_eq!(cpu_list("0-2,5"), [0, 1, 2, 5]);
    }

    #[test]
    fn a_layout_fits_the_site_or_says_what_to_change() {
        let site = Site {
            cores_per_node: 4,
            max_nodes: 2,
            ..Site::local()
        };
        let layout = |nodes, ranks, threads| Layout {
            nodes,
            ranks,
            threads,
        };
        assert_eq!(layout(2, 8, 1).check(&site, false), Ok(()));
        assert_eq!(layout(2, 4, 2).ranks_per_node(), 2);
        let err = layout(3, 3, 1).check(&site, false).unwrap_err();
        assert!(err.contains("`max_nodes`"), "{err}");
        let err = layout(2, 3, 1).check(&site, false).unwrap_err();
        assert!(err.contains("spread evenly"), "{err}");
        let over = layout(1, 4, 2);
        assert!(over.oversubscribes(&site));
        let err = over.check(&site, false).unwrap_err();
        assert!(
            err.contains("need 8 cores") && err.contains("oversubscribe = true"),
            "{err}"
        );
        assert_eq!(over.check(&site, true), Ok(()));
    }
}
