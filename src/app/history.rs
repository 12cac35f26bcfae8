//! Undo and redo of project edits: every edit stores the whole project before it (projects are
//! small: strokes and keys, never pixels).

use crate::project::Project;

/// Most undo steps kept.
pub const MAX_UNDO: usize = 200;

/// Snapshots before each edit (undo) and after each undo (redo).
#[derive(Default)]
pub struct History {
    undo: Vec<(String, Project)>,
    redo: Vec<(String, Project)>,
}

impl History {
    /// Records that `before` was replaced by an edit named `label`; clears the redo list.
    pub fn record(&mut self, label: &str, before: Project) {
        self.undo.push((label.to_string(), before));
        if self.undo.len() > MAX_UNDO {
            self.undo.remove(0);
        }
        self.redo.clear();
    }

    /// Undoes the last edit of `current`: returns the project to go back to and the edit's
    /// name.
    pub fn undo(&mut self, current: &Project) -> Option<(String, Project)> {
        let (label, before) = self.undo.pop()?;
        self.redo.push((label.clone(), current.clone()));
        Some((label, before))
    }

    /// Redoes the last undone edit.
    pub fn redo(&mut self, current: &Project) -> Option<(String, Project)> {
        let (label, after) = self.redo.pop()?;
        self.undo.push((label.clone(), current.clone()));
        Some((label, after))
    }

    /// The name of the edit [`History::undo`] would undo.
    pub fn undo_label(&self) -> Option<&str> {
        self.undo.last().map(|(l, _)| l.as_str())
    }

    /// The name of the edit [`History::redo`] would redo.
    pub fn redo_label(&self) -> Option<&str> {
        self.redo.last().map(|(l, _)| l.as_str())
    }

    /// How many edits can be undone and redone.
    pub fn depths(&self) -> (usize, usize) {
        (self.undo.len(), self.redo.len())
    }

    /// Forgets everything (a new document).
    pub fn clear(&mut self) {
        self.undo.clear();
        self.redo.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undo_redo_walks_back_and_forth() {
        let mut h = History::default();
        let p0 = Project::new("a.jpg");
        let mut p1 = p0.clone();
        p1.output.frames = 7;
        let mut p2 = p1.clone();
        p2.output.fps = 12.0;
        h.record("frames", p0.clone());
        h.record("fps", p1.clone());
        assert_eq!(h.undo_label(), Some("fps"));
        let (label, back) = h.undo(&p2).unwrap();
        assert_eq!((label.as_str(), &back), ("fps", &p1));
        let (_, back) = h.undo(&back).unwrap();
        assert_eq!(back, p0);
        assert!(h.undo(&back).is_none());
        let (_, fwd) = h.redo(&back).unwrap();
        assert_eq!(fwd, p1);
        // A new edit drops the redo list.
        h.record("other", fwd.clone());
        assert!(h.redo(&fwd).is_none());
    }

    #[test]
    fn history_is_bounded() {
        let mut h = History::default();
        for _ in 0..MAX_UNDO + 10 {
            h.record("x", Project::new("a.jpg"));
        }
        let mut n = 0;
        let p = Project::new("a.jpg");
        while h.undo(&p).is_some() {
            n += 1;
        }
        assert_eq!(n, MAX_UNDO);
    }
}
