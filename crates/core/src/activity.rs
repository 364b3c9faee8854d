//! The nine activity classes, in the order used everywhere (class index 0..8): model outputs,
//! datasets, messages, metrics and reports.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Activity {
    Crawling = 0,
    FallingDown = 1,
    GettingUp = 2,
    LyingDown = 3,
    Running = 4,
    SittingOnFloor = 5,
    Standing = 6,
    Walking = 7,
    WalkingUnsteadily = 8,
}

impl Activity {
    pub const COUNT: usize = 9;
    pub const ALL: [Activity; Self::COUNT] = [
        Activity::Crawling,
        Activity::FallingDown,
        Activity::GettingUp,
        Activity::LyingDown,
        Activity::Running,
        Activity::SittingOnFloor,
        Activity::Standing,
        Activity::Walking,
        Activity::WalkingUnsteadily,
    ];

    pub const fn index(self) -> usize {
        self as usize
    }

    pub fn from_index(index: usize) -> Option<Self> {
        Self::ALL.get(index).copied()
    }

    /// The snake_case label used in messages, datasets and reports.
    pub const fn label(self) -> &'static str {
        match self {
            Activity::Crawling => "crawling",
            Activity::FallingDown => "falling_down",
            Activity::GettingUp => "getting_up",
            Activity::LyingDown => "lying_down",
            Activity::Running => "running",
            Activity::SittingOnFloor => "sitting_on_floor",
            Activity::Standing => "standing",
            Activity::Walking => "walking",
            Activity::WalkingUnsteadily => "walking_unsteadily",
        }
    }

    pub fn from_label(label: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|a| a.label() == label)
    }

    /// On the floor: the postures after which a person who does not get up needs help.
    pub const fn is_on_floor(self) -> bool {
        matches!(
            self,
            Activity::LyingDown | Activity::SittingOnFloor | Activity::Crawling
        )
    }
}

impl Activity {
    /// On one's feet: standing, walking, running or walking unsteadily.
    pub const fn is_upright(self) -> bool {
        matches!(
            self,
            Activity::Standing
                | Activity::Walking
                | Activity::Running
                | Activity::WalkingUnsteadily
        )
    }

    /// The class with the highest score (probability or logit) and that score; the first
    /// one in class order on ties.
    pub fn most_likely(scores: &[f32; Activity::COUNT]) -> (Activity, f32) {
        let mut best = 0;
        for (i, &p) in scores.iter().enumerate() {
            if p > scores[best] {
                best = i;
            }
        }
        (Activity::ALL[best], scores[best])
    }
}

impl std::fmt::Display for Activity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.label())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_most_likely_class_is_the_first_on_ties() {
        let mut scores = [0.0; Activity::COUNT];
        scores[Activity::Walking.index()] = 0.9;
        assert_eq!(Activity::most_likely(&scores), (Activity::Walking, 0.9));
        scores[Activity::FallingDown.index()] = 0.9;
        assert_eq!(Activity::most_likely(&scores).0, Activity::FallingDown);
        assert_eq!(Activity::most_likely(&[-3.0; 9]).0, Activity::ALL[0]);
    }

    #[test]
    fn index_and_label_round_trip() {
        for (i, a) in Activity::ALL.into_iter().enumerate() {
            assert_eq!(a.index(), i);
            assert_eq!(Activity::from_index(i), Some(a));
            assert_eq!(Activity::from_label(a.label()), Some(a));
        }
        assert_eq!(Activity::from_index(9), None);
        assert_eq!(Activity::from_label("dancing"), None);
    }

    #[test]
    fn upright_on_the_floor_falling_and_getting_up_cover_every_class_once() {
        for a in Activity::ALL {
            let kinds = [
                a.is_upright(),
                a.is_on_floor(),
                a == Activity::FallingDown,
                a == Activity::GettingUp,
            ];
            assert_eq!(kinds.iter().filter(|&&k| k).count(), 1, "{a}");
        }
    }
}
