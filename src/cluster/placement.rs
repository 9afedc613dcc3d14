//! Where one run's ranks and threads go on a site's nodes ([`Layout`]), and whether the
//! site holds them: the nodes it has, ranks spread evenly over the nodes, and ranks ×
//! threads within its cores unless the user insists.

use crate::cluster::site::Site;

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

#[cfg(test)]
mod tests {
    use super::*;

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
