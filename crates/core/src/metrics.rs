//! Classification metrics over the nine activities: confusion matrix, accuracy, per-class
//! precision / recall / F1, and the two usual F1 averages (macro and support-weighted), so our
//! figures can be put beside the paper's whichever average it used.
//!
//! Conventions (the same as scikit-learn with `zero_division=0`): a precision, recall or F1
//! whose denominator is zero counts as 0. The macro average runs over the classes that occur
//! in the truth or in the predictions (a class absent from both says nothing about the
//! model); the weighted average weights each class by its support (true count). An empty
//! matrix has accuracy 0 and all averages 0.

use serde::Serialize;

use crate::activity::Activity;

const N: usize = Activity::COUNT;

/// Counts of (true activity, predicted activity) pairs. Rows are the truth, columns the
/// prediction, both in the class order of [`Activity::ALL`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ConfusionMatrix {
    counts: [[u64; N]; N],
}

/// Precision, recall and F1 of one class.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ClassMetrics {
    pub activity: Activity,
    pub precision: f64,
    pub recall: f64,
    pub f1: f64,
    /// How many samples truly are of this class.
    pub support: u64,
    /// How many samples were predicted as this class.
    pub predicted: u64,
}

/// Everything an evaluation report needs, ready to serialise (e.g. as `metrics.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MetricsReport {
    pub samples: u64,
    pub accuracy: f64,
    /// Unweighted mean of the per-class F1 over the classes present in truth or prediction.
    pub macro_f1: f64,
    /// Mean of the per-class F1 weighted by support.
    pub weighted_f1: f64,
    /// One entry per class, in class order.
    pub per_class: Vec<ClassMetrics>,
    /// `confusion[truth][predicted]`, class order.
    pub confusion: Vec<Vec<u64>>,
}

impl ConfusionMatrix {
    pub fn new() -> Self {
        Self::default()
    }

    /// Builds a matrix from (truth, prediction) pairs.
    pub fn from_pairs(pairs: impl IntoIterator<Item = (Activity, Activity)>) -> Self {
        let mut matrix = Self::new();
        for (truth, predicted) in pairs {
            matrix.add(truth, predicted);
        }
        matrix
    }

    pub fn add(&mut self, truth: Activity, predicted: Activity) {
        self.counts[truth.index()][predicted.index()] += 1;
    }

    /// Adds another matrix (e.g. from another episode or thread).
    pub fn merge(&mut self, other: &ConfusionMatrix) {
        for (row, other_row) in self.counts.iter_mut().zip(&other.counts) {
            for (cell, other_cell) in row.iter_mut().zip(other_row) {
                *cell += other_cell;
            }
        }
    }

    /// `counts()[truth][predicted]`.
    pub fn counts(&self) -> &[[u64; N]; N] {
        &self.counts
    }

    pub fn total(&self) -> u64 {
        self.counts.iter().flatten().sum()
    }

    fn correct(&self) -> u64 {
        (0..N).map(|i| self.counts[i][i]).sum()
    }

    fn support(&self, class: usize) -> u64 {
        self.counts[class].iter().sum()
    }

    fn predicted(&self, class: usize) -> u64 {
        self.counts.iter().map(|row| row[class]).sum()
    }

    /// Share of samples predicted correctly; 0 for an empty matrix.
    pub fn accuracy(&self) -> f64 {
        ratio(self.correct(), self.total())
    }

    pub fn class_metrics(&self, activity: Activity) -> ClassMetrics {
        let class = activity.index();
        let hits = self.counts[class][class];
        let support = self.support(class);
        let predicted = self.predicted(class);
        let precision = ratio(hits, predicted);
        let recall = ratio(hits, support);
        let f1 = if precision + recall > 0.0 {
            2.0 * precision * recall / (precision + recall)
        } else {
            0.0
        };
        ClassMetrics {
            activity,
            precision,
            recall,
            f1,
            support,
            predicted,
        }
    }

    /// Unweighted mean F1 over the classes present in the truth or the predictions.
    pub fn macro_f1(&self) -> f64 {
        let present: Vec<ClassMetrics> = Activity::ALL
            .into_iter()
            .map(|a| self.class_metrics(a))
            .filter(|m| m.support > 0 || m.predicted > 0)
            .collect();
        if present.is_empty() {
            return 0.0;
        }
        present.iter().map(|m| m.f1).sum::<f64>() / present.len() as f64
    }

    /// F1 averaged over classes, weighted by support.
    pub fn weighted_f1(&self) -> f64 {
        let total = self.total();
        if total == 0 {
            return 0.0;
        }
        Activity::ALL
            .into_iter()
            .map(|a| self.class_metrics(a))
            .map(|m| m.f1 * m.support as f64)
            .sum::<f64>()
            / total as f64
    }

    pub fn report(&self) -> MetricsReport {
        MetricsReport {
            samples: self.total(),
            accuracy: self.accuracy(),
            macro_f1: self.macro_f1(),
            weighted_f1: self.weighted_f1(),
            per_class: Activity::ALL
                .into_iter()
                .map(|a| self.class_metrics(a))
                .collect(),
            confusion: self.counts.iter().map(|row| row.to_vec()).collect(),
        }
    }
}

fn ratio(numerator: u64, denominator: u64) -> f64 {
    if denominator == 0 {
        0.0
    } else {
        numerator as f64 / denominator as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use Activity::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn empty_matrix_is_all_zero_not_nan() {
        let report = ConfusionMatrix::new().report();
        assert_eq!(report.samples, 0);
        assert_eq!(report.accuracy, 0.0);
        assert_eq!(report.macro_f1, 0.0);
        assert_eq!(report.weighted_f1, 0.0);
        for m in &report.per_class {
            assert_eq!((m.precision, m.recall, m.f1), (0.0, 0.0, 0.0));
        }
    }

    #[test]
    fn hand_computed_example() {
        // walking: 3 true, 2 right, 1 taken for running; running: 1 true, right;
        // standing: 1 true, taken for walking.
        let m = ConfusionMatrix::from_pairs([
            (Walking, Walking),
            (Walking, Walking),
            (Walking, Running),
            (Running, Running),
            (Standing, Walking),
        ]);
        assert_eq!(m.total(), 5);
        assert_eq!(m.counts()[Walking.index()][Running.index()], 1);
        assert!(close(m.accuracy(), 3.0 / 5.0));

        let walking = m.class_metrics(Walking);
        assert!(close(walking.precision, 2.0 / 3.0));
        assert!(close(walking.recall, 2.0 / 3.0));
        assert!(close(walking.f1, 2.0 / 3.0));
        let running = m.class_metrics(Running);
        assert!(close(running.precision, 0.5));
        assert!(close(running.recall, 1.0));
        assert!(close(running.f1, 2.0 / 3.0));
        let standing = m.class_metrics(Standing);
        assert_eq!(
            (standing.precision, standing.recall, standing.f1),
            (0.0, 0.0, 0.0)
        );
        assert_eq!(standing.support, 1);

        // Macro over the three present classes; absent classes (e.g. crawling) do not count.
        assert!(close(m.macro_f1(), (2.0 / 3.0 + 2.0 / 3.0 + 0.0) / 3.0));
        assert!(close(m.weighted_f1(), (3.0 * 2.0 / 3.0 + 2.0 / 3.0) / 5.0));
    }

    #[test]
    fn perfect_predictions_score_one() {
        let m = ConfusionMatrix::from_pairs(Activity::ALL.into_iter().map(|a| (a, a)));
        let r = m.report();
        assert_eq!(r.accuracy, 1.0);
        assert_eq!(r.macro_f1, 1.0);
        assert_eq!(r.weighted_f1, 1.0);
        assert_eq!(r.confusion.len(), 9);
        assert!(r.per_class.iter().all(|c| c.f1 == 1.0));
    }

    #[test]
    fn merge_adds_counts() {
        let mut a = ConfusionMatrix::from_pairs([(Crawling, Crawling)]);
        let b = ConfusionMatrix::from_pairs([(Crawling, LyingDown), (FallingDown, FallingDown)]);
        a.merge(&b);
        assert_eq!(a.total(), 3);
        assert_eq!(a.counts()[Crawling.index()][LyingDown.index()], 1);
    }
}
