//! Fall alerts from the stream of per-scan activity probabilities.
//!
//! Two alerts, each raised once per incident:
//! - `FallDetected`: `falling_down` is the most likely class on `fall_min_scans` consecutive
//!   visible scans with a mean probability of at least `fall_probability`, the run starting at
//!   most `fall_from_upright_s` after the person was last upright (or, with
//!   `fall_on_first_sight`, before any posture of the person was confirmed), and the person then
//!   lands on the floor within `fall_then_floor_s` without being upright for
//!   `rearm_upright_s` first (a stagger or a sudden stop the model reads as falling ends
//!   upright; a fall ends on the floor); or a descent: lying down is
//!   confirmed at most `descent_max_s` after the person was last upright or getting up (a
//!   fall is short and easily missed, the lying that follows is not; a failed attempt to
//!   stand ends lying too, while getting up misread as falling is the model's commonest
//!   false fall, so getting up starts a `falling_down` run only once read so for
//!   `descent_getting_up_s`, with `fall_from_getting_up`, and such a run must land on lying as
//!   sure as a descent's). Both are confirmed postures,
//!   not one scan: a person crawling whom the classifier takes for walking for a scan or two
//!   has not left the floor, and cannot fall from there. The lying that makes a descent must
//!   also look like a body on the floor: its points stretch at least `descent_min_length_m`
//!   on most of the scans that confirm the floor posture (a standing person misread as lying
//!   is one or two legs, and a crawler seen end-on stretches that far on a stray scan), and
//!   the classifier is sure of it: on those of the scans it reads as lying, `lying_down` has
//!   at least `descent_min_probability` on most (a fallen body lies still and reads as lying
//!   at once; a crawler the model takes for lying for a moment keeps moving, and the model
//!   hesitates). A descent from upright that the classifier read as falling on a few scans
//!   in pieces (`broken_fall_run_scans`), never on `fall_min_scans` in a row, is evidence as
//!   a run is, and lands on lying as a run does (`landing_min_probability`); so does a fall
//!   back down read in pieces after `descent_getting_up_s` of getting up, landing as a run
//!   from getting up does.
//! - `PersonDown`: the person has been on the floor (lying, sitting on the floor or crawling,
//!   [`Activity::is_on_floor`]) for `down_after_s` without being seen getting up. The clock
//!   starts at a detected fall or at the first confirmed on-floor scan, so a fall the robot did
//!   not see still gives this alert once the robot finds the person down. Time out of sight
//!   does not reset the clock (a person lying behind the sofa is still down; only seeing them
//!   get up, or upright for `down_ends_upright_s`, ends the incident; after a recognised
//!   fall, only readings sure of it, `down_ends_min_probability`), but each stretch of it
//!   counts at most `down_unseen_counts_s`: the robot cannot vouch for a person it does not
//!   see, and people who got up out of sight and sat down again were alerted as down. A
//!   person down who is seen to cover ground faster than anyone can on the floor
//!   (`down_travel_m` within `down_travel_within_s`) has evidently been up, whatever the
//!   classifier reads of them: the clock starts again there (a walker seen in glimpses is
//!   misread as sitting or crawling).
//!
//! Crawling counts as on the floor: a fallen person who crawls towards a phone still needs
//! help, and a person who crawls for `down_after_s` on purpose is rare enough in a home to
//! accept the alert (raise `down_after_s` where children crawl about).
//!
//! Hysteresis: postures change only after `confirm_scans` consecutive scans agree (one
//! flickering scan changes nothing; a stretch out of sight longer than `glimpse_gap_s`
//! starts them again, as it does a `falling_down` run, and every "seen for so long" below
//! counts only time seen), and after an alert its kind is re-armed only once the
//! person has been seen upright (standing, walking, running, walking unsteadily) for
//! `rearm_upright_s` (a moment read as falling does not restart that clock: a standing person
//! is often misread so). `FallDetected` is also re-armed by being read as getting up on every
//! scan seen for `rearm_getting_up_s`: one fall, one alert, but a person who falls back while
//! struggling up has fallen twice; with `fall_from_getting_up`, so is a `falling_down` run
//! that begins after the person was read as getting up for `descent_getting_up_s` since the
//! alert, and lands: the model reads a person rising as falling now and then, which breaks
//! the unbroken second. Time going backwards (a replay restarting) clears everything.

use std::collections::VecDeque;

use glam::DVec2;
use serde::{Deserialize, Serialize};

use crate::activity::Activity;
use crate::stats::upper_median;

/// Thresholds of the fall alerts (`config/classifier.yaml`, section `fall_alert`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FallAlertConfig {
    /// Minimum mean probability of `falling_down` over `fall_min_scans` consecutive scans
    /// that read it as the most likely class: a fall read at 0.6-0.9 scan by scan is still a
    /// fall, where a threshold on every scan broke the run at each dip.
    pub fall_probability: f32,
    /// Consecutive scans read as `falling_down` needed for `FallDetected`.
    pub fall_min_scans: u32,
    /// Such a run raises `FallDetected` only once the person then lands on the floor (lying,
    /// with `fall_lands_lying`; else any floor posture) within this time of the run (the
    /// landing's first scan; its confirmation may come after): the alert comes on landing
    /// instead of during the fall, and a stagger or a sudden stop that the model reads as
    /// falling, after which the person stays upright, raises none. Being read upright for a
    /// moment in between does not cancel it: the model misreads a fallen person as standing
    /// for a moment (seed 2 of `lidar-har alerts`, docs/classifier.md); being upright for
    /// `fall_cancel_upright_s` does. Seconds; 0 raises it at the run itself.
    pub fall_then_floor_s: f64,
    /// A `falling_down` run waiting for its landing is dropped when the person is confirmed
    /// upright this long after its last scan read as falling (a run counts while the person
    /// is still falling), not on the floor or getting up in between: they
    /// staggered and walked on. A fallen person misread as standing is so for a few tenths
    /// of a second; an unsteady walker whose stagger was read as falling walked on for 0.95 s
    /// before being misread as lying (seed 1 episode 179 of `lidar-har alerts`,
    /// docs/classifier.md, session 35). Seconds.
    pub fall_cancel_upright_s: f64,
    /// The landing that confirms a `falling_down` run must be read as lying without doubt
    /// (`landing_min_probability`): a person who stops short, read as falling for a moment,
    /// and then sits down, or who sits down fast, lands sitting (seed 3 of `lidar-har
    /// alerts`, docs/classifier.md, session 15).
    pub fall_lands_lying: bool,
    /// The median p(lying_down) over `confirm_scans` consecutive scans read as lying must
    /// reach this for a landing; the scans slide along the lying run. Lower than
    /// `descent_min_probability`: the `falling_down` run is evidence of its own, and no
    /// false alert came from a run's landing (docs/classifier.md, session 20).
    pub landing_min_probability: f64,
    /// ... and the median length of the person's points over those scans must reach this: a
    /// standing person read as falling and then as lying is one or two legs (0.3-0.5 m),
    /// while 197 of 203 alerted landings on the five alert seeds stretched 0.8 m or more
    /// and all 0.5 m or more. Lower than `descent_min_length_m`, as the run is evidence of
    /// its own. Metres; 0 drops the check (as do unknown lengths).
    pub landing_min_length_m: f64,
    /// Time on the floor without getting up before `PersonDown`, seconds.
    pub down_after_s: f64,
    /// Consecutive scans that must agree before the posture (on floor / getting up / upright)
    /// is taken as changed.
    pub confirm_scans: u32,
    /// Time the person must be seen upright before a new incident can raise alerts, seconds.
    pub rearm_upright_s: f64,
    /// After `FallDetected`, being read as getting up on every scan seen for this long (and
    /// at least `confirm_scans`) re-arms it, not `PersonDown`: a person who struggles up
    /// from a fall and falls back has fallen again, and is often never upright in between.
    /// Seconds; 0 turns this off (only `rearm_upright_s` re-arms).
    pub rearm_getting_up_s: f64,
    /// A person down is up again once confirmed getting up, or confirmed upright for this
    /// long: a fallen person sitting on the floor is misread as walking unsteadily or
    /// standing for a few tenths of a second every few seconds, and each such moment
    /// restarted the `down_after_s` clock. Seconds; 0: at the upright posture's confirmation.
    pub down_ends_upright_s: f64,
    /// After a fall recognised in the spell, only when at least half of the scans read as
    /// that posture since it was first read had at least this probability: a fallen person
    /// sitting on the floor is misread as standing at 0.5-0.7 for a second or more, or as
    /// getting up at 0.4-0.7, and each such reading ended the spell; a person really up is
    /// mostly read so at 0.9 or more. Not without a fall: a person standing still is read at
    /// 0.5-0.9 too, and 0.9 everywhere gave 71 false `PersonDown` in 44 h against 1
    /// (docs/classifier.md, session 42). 0: every reading.
    pub down_ends_min_probability: f64,
    /// ... and getting up only once read so for this long (seconds; upright:
    /// `down_ends_upright_s`): a fallen person sitting up is read as getting up, surely, for
    /// a few tenths of a second.
    pub down_ends_getting_up_s: f64,
    /// Seen upright or getting up, then confirmed lying on the floor within this time:
    /// `FallDetected` even when no scan looked like `falling_down` (a fall is short; lying is
    /// not). Seconds; 0 turns this off.
    pub descent_max_s: f64,
    /// Getting up starts a descent only once read so on every scan for this long (upright:
    /// once confirmed): a person struggling up and falling back is read getting up for a
    /// second or more, a crawler the model takes for getting up for a moment and then for
    /// lying fell nowhere (seed 1 episode 379 of `lidar-har alerts`, docs/classifier.md,
    /// session 35). Seconds; 0: once confirmed.
    pub descent_getting_up_s: f64,
    /// A run of `falling_down` scans counts only when it starts at most this long after the
    /// person was last confirmed upright: a fall starts from standing or walking, and getting
    /// up or crawling misread as falling does not. Seconds; 0 drops the requirement.
    pub fall_from_upright_s: f64,
    /// A run of `falling_down` scans that begins before any posture of the person was
    /// confirmed (at start-up or after a reset) counts although nobody saw them upright
    /// before: the robot may come upon someone as they fall. `fall_from_upright_s` cannot
    /// rule such a run out, having nothing to go by. Not only the first scan seen: the
    /// model's first readings of a stream, with half a window behind them, are often some
    /// other class for a few scans (before session 44, the first scan only).
    pub fall_on_first_sight: bool,
    /// A run of `falling_down` scans also counts when it starts at most `fall_from_upright_s`
    /// after the person was read as getting up on every scan for `descent_getting_up_s` (as
    /// a descent may start from there), landing only on lying as sure as a descent's
    /// (`descent_min_probability`: a crawler read as getting up, then as falling, landed on
    /// lying read at 0.79-0.88, seed 6 episode 139). After a `FallDetected`, such a run
    /// that began after getting up again and lands is a new fall without waiting for
    /// `rearm_getting_up_s`. A person who struggles up and falls back is read as getting up
    /// for half a second, then as falling on 10-27 scans and as lying: the model's reading
    /// of a rising person as falling now and then broke the unbroken second that re-arms, and
    /// the run did not start from upright (15 of the 80 falls missed on seeds 1-5 of
    /// `lidar-har alerts`, docs/classifier.md, session 38). False: from upright only.
    pub fall_from_getting_up: bool,
    /// ... but a run from getting up whose mean over `fall_min_scans` scans reaches this at
    /// any point lands at `landing_min_probability`, as a run from upright does: the crawler
    /// above was read as falling at a mean of 0.7, while a person who fell back, read as
    /// falling on 14 scans at a mean of up to 0.81, landed on lying read at 0.73-0.90 and was
    /// alerted 2 s late (seed 1 episode 5, docs/classifier.md, session 40). 0 turns this off.
    pub sure_fall_run_probability: f64,
    /// A descent counts only when, over the scans that confirm lying, the person's points
    /// stretch at least this far along their main axis (the median of those scans): a body on
    /// the floor is over a metre long at ankle height, while a standing person the classifier
    /// takes for lying for a few scans is one or two legs, and a crawler seen end-on reaches
    /// it on a stray scan only. Metres; 0 drops the check (as do unknown lengths).
    pub descent_min_length_m: f64,
    /// A descent counts only when, on the scans that confirm the floor posture and are read
    /// as lying, `lying_down` has at least this probability (their median): after a fall the
    /// model reads lying at once (0.94-1.00 on the traced falls), a crawler it takes for
    /// lying for a moment with doubt (0.49-0.79; with the session-17 model the false descents
    /// left were crawlers read at up to 0.9): `lidar-har alerts`, docs/classifier.md.
    /// 0 drops the check.
    pub descent_min_probability: f64,
    /// A descent from upright that the classifier read as falling on at least this many
    /// scans since the person was last read upright, though never on `fall_min_scans` in a
    /// row, lands as a `falling_down` run does: on the first `confirm_scans` scans read as
    /// lying, at `landing_min_probability` rather than `descent_min_probability`. A fall seen
    /// in full view was read as falling on 2 and 3 scans with sitting between, then as lying
    /// at 0.58-0.94 (seed 1 episode 9 of `lidar-har alerts`, docs/classifier.md, session
    /// 39). With `fall_from_getting_up`, the same holds for a fall back down after the
    /// person was read as getting up for `descent_getting_up_s`, landing at
    /// `descent_min_probability` and re-arming the alert as such a run does (session 40).
    /// 0 turns this off.
    pub broken_fall_run_scans: u32,
    /// ... and only after the person had been upright for this long: a crawler read as
    /// walking for 0.8-1 s, then as falling on a few scans and as lying, fell nowhere (seeds
    /// 1, 5 and 6 of `lidar-har alerts`). Seconds.
    pub broken_fall_run_upright_s: f64,
    /// `PersonDown` waits while any scan since the person was last confirmed on the floor
    /// (`down_seen_within_s`) read them upright or getting up, even unconfirmed: a person
    /// seen on the floor who gets up where the robot sees them only in glimpses is otherwise
    /// alerted as down (seeds 1 and 4 of `lidar-har alerts`, docs/classifier.md). The alert
    /// comes once they are confirmed on the floor again; being confirmed upright ends it.
    pub down_waits_on_upright_glimpse: bool,
    /// `PersonDown` is raised only while the person was last confirmed on the floor (a run
    /// of `confirm_scans` visible scans read on the floor) within this time; otherwise it
    /// waits until they are found on the floor again. A person seen sitting who gets up
    /// out of the robot's sight is otherwise alerted as down 15 s later (seeds 1 and 2 of
    /// `lidar-har alerts`, docs/classifier.md). Seconds; 0 drops the requirement.
    pub down_seen_within_s: f64,
    /// Whether a run of crawling counts as the person confirmed on the floor: the fresh
    /// evidence `PersonDown` waits for (`down_seen_within_s`, `down_waits_on_upright_glimpse`).
    /// Crawling keeps the person down either way, but the alert is for a person found lying
    /// or sitting; the false alerts left after session 14 were people found crawling after
    /// getting up out of sight (docs/classifier.md, session 15).
    pub crawling_shows_down: bool,
    /// Being confirmed on the floor (for the two holds above) takes `confirm_scans` scans in
    /// a row with the person in view: read on the floor in glimpses between hidden scans is
    /// how the model sees a walker far down a hall (seed 3 episode 366, seed 5 episode 233
    /// of `lidar-har alerts`: PERSON_DOWN on walkers, docs/classifier.md, session 35). A
    /// person truly down and in view is seen so for longer. False: the glimpses add up.
    pub down_found_in_view: bool,
    /// Evidence that includes scans read as lying counts only when the person's points
    /// stretch at least this far (metres) on those scans: the median over the last
    /// `down_lying_length_scans` scans read as lying since the person was last up (scans of
    /// unknown length left out). A person standing still whom the model reads as lying is one or two
    /// legs, 0.31 m on most scans and 0.6-0.8 m on a few (seed 4 episode 609 of `lidar-har
    /// alerts`); a body on the floor seen in part stretches 0.45-0.9 m scan by scan (seed 3
    /// episode 625). A fall recognised in the incident vouches for the floor on its own: a
    /// person sitting on the floor read as lying is as short as a standing one (0.23 m; seed 1
    /// episode 651, alerted as fallen and then down for 40 s). 0 turns the check off.
    pub down_lying_min_length_m: f64,
    /// How many of the latest scans read as lying that median is over: a few legs' scans
    /// stretch as far as a body's, so a run of `confirm_scans` alone is not enough.
    pub down_lying_length_scans: u32,
    /// Each stretch in which the person is out of sight counts towards `down_after_s` for at
    /// most this long: the robot cannot vouch for a person it does not see staying down, and
    /// the false `PersonDown` were people who got up out of sight and sat down again.
    /// Seconds; 0 counts every stretch in full.
    pub down_unseen_counts_s: f64,
    /// A person down who is seen to cover this much ground within `down_travel_within_s` has
    /// evidently been up, whatever the classifier reads: the `down_after_s` clock starts
    /// again there (it restarts rather than ends, so that a person who then sits or lies
    /// while still read on the floor is alerted in time). A walker seen in glimpses is
    /// misread as sitting or crawling, and covers 1 m/s; a crawler covers 0.3 m/s. Only
    /// positions seen since the spell began count (a fall carries the body on up to the
    /// landing that confirms it), and a body on the floor seen in part, or sitting up, moves
    /// the localiser's position by up to 1.2 m at once. Metres; 0 turns this off.
    pub down_travel_m: f64,
    /// The time within which `down_travel_m` must be covered, seconds; 0 turns it off too.
    pub down_travel_within_s: f64,
    /// A person down read as falling, in a run that counts but not as a fall (not upright
    /// just before, `fall_from_upright_s`), has been up: nobody falls from the floor. Their
    /// `down_after_s` clock starts again at the run's start, and `down_travel_m` counts
    /// ground from there, as for any new spell. A person who got up unseen as
    /// such and sat straight down again was read getting up for 4 scans, then falling for
    /// 1.2 s (seed 4 episode 327 of `lidar-har alerts`, docs/classifier.md, session 36).
    pub down_restarts_on_fall_run: bool,
    /// The longest stretch out of sight (from one scan the person is seen on to the next, with
    /// at least one scan between that does not see them) that still joins the readings on
    /// either side: up to it, a run of readings (the posture being
    /// confirmed, `falling_down`, lying) runs on and the stretch counts as time seen; past it,
    /// every run starts again and the stretch counts as time out of sight. A walker read on the
    /// floor for a scan or two as they left view, then found sitting a minute later, was taken
    /// as on the floor since that first reading, and 0.3 s seen upright around a second out of
    /// sight re-armed an alert. Getting up, people were out of sight for 0.4-0.5 s (seed 2
    /// episodes 6 and 37 of `lidar-har alerts`): 0.25 s broke those runs, which lost a fall
    /// (not re-armed) and a spell's end (a false `PersonDown`; docs/classifier.md, session 56).
    /// Seconds; 0: any scan out of sight starts the runs again. Two scans in a row that see
    /// the person are never a stretch out of sight, however far apart (a value under the scan
    /// period used to break every run, and no alert was ever raised).
    pub glimpse_gap_s: f64,
}

impl Default for FallAlertConfig {
    fn default() -> Self {
        Self {
            fall_probability: 0.7,
            fall_min_scans: 5,
            fall_then_floor_s: 3.0,
            fall_cancel_upright_s: 0.75,
            fall_lands_lying: true,
            landing_min_probability: 0.8,
            landing_min_length_m: 0.6,
            down_after_s: 15.0,
            confirm_scans: 5,
            rearm_upright_s: 1.5,
            rearm_getting_up_s: 1.0,
            down_ends_upright_s: 1.0,
            down_ends_min_probability: 0.9,
            down_ends_getting_up_s: 0.5,
            descent_max_s: 3.0,
            descent_getting_up_s: 0.5,
            fall_from_upright_s: 3.0,
            fall_on_first_sight: true,
            fall_from_getting_up: true,
            sure_fall_run_probability: 0.8,
            descent_min_length_m: 0.8,
            descent_min_probability: 0.9,
            broken_fall_run_scans: 3,
            broken_fall_run_upright_s: 1.5,
            down_waits_on_upright_glimpse: true,
            down_seen_within_s: 5.0,
            crawling_shows_down: false,
            down_found_in_view: true,
            down_lying_min_length_m: 0.5,
            down_lying_length_scans: 20,
            down_unseen_counts_s: 1.0,
            down_travel_m: 2.0,
            down_travel_within_s: 2.0,
            down_restarts_on_fall_run: true,
            glimpse_gap_s: 0.6,
        }
    }
}

/// Why a fall-alert configuration cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FallConfigError {
    #[error("fall_alert.{name} = {value} is out of range ({expected})")]
    OutOfRange {
        name: &'static str,
        value: f64,
        expected: &'static str,
    },
}

impl FallAlertConfig {
    pub fn validate(&self) -> Result<(), FallConfigError> {
        let check = |name, value: f64, ok: bool, expected| {
            if ok {
                Ok(())
            } else {
                Err(FallConfigError::OutOfRange {
                    name,
                    value,
                    expected,
                })
            }
        };
        let at_least_zero = |name, value: f64| {
            check(
                name,
                value,
                value.is_finite() && value >= 0.0,
                "finite, >= 0",
            )
        };
        let probability =
            |name, value: f64| check(name, value, (0.0..=1.0).contains(&value), "0..=1");
        probability("fall_probability", self.fall_probability as f64)?;
        let n = self.fall_min_scans as f64;
        check("fall_min_scans", n, self.fall_min_scans >= 1, ">= 1")?;
        at_least_zero("fall_then_floor_s", self.fall_then_floor_s)?;
        at_least_zero("fall_cancel_upright_s", self.fall_cancel_upright_s)?;
        let n = self.confirm_scans as f64;
        check("confirm_scans", n, self.confirm_scans >= 1, ">= 1")?;
        at_least_zero("down_after_s", self.down_after_s)?;
        at_least_zero("rearm_upright_s", self.rearm_upright_s)?;
        at_least_zero("rearm_getting_up_s", self.rearm_getting_up_s)?;
        at_least_zero("down_ends_upright_s", self.down_ends_upright_s)?;
        at_least_zero("down_ends_getting_up_s", self.down_ends_getting_up_s)?;
        at_least_zero("descent_max_s", self.descent_max_s)?;
        at_least_zero("descent_getting_up_s", self.descent_getting_up_s)?;
        at_least_zero("fall_from_upright_s", self.fall_from_upright_s)?;
        at_least_zero("broken_fall_run_upright_s", self.broken_fall_run_upright_s)?;
        at_least_zero("descent_min_length_m", self.descent_min_length_m)?;
        at_least_zero("landing_min_length_m", self.landing_min_length_m)?;
        at_least_zero("down_seen_within_s", self.down_seen_within_s)?;
        at_least_zero("down_lying_min_length_m", self.down_lying_min_length_m)?;
        let n = self.down_lying_length_scans as f64;
        check(
            "down_lying_length_scans",
            n,
            self.down_lying_length_scans >= 1,
            ">= 1",
        )?;
        at_least_zero("down_unseen_counts_s", self.down_unseen_counts_s)?;
        at_least_zero("down_travel_m", self.down_travel_m)?;
        at_least_zero("down_travel_within_s", self.down_travel_within_s)?;
        at_least_zero("glimpse_gap_s", self.glimpse_gap_s)?;
        probability("landing_min_probability", self.landing_min_probability)?;
        probability("sure_fall_run_probability", self.sure_fall_run_probability)?;
        probability("down_ends_min_probability", self.down_ends_min_probability)?;
        probability("descent_min_probability", self.descent_min_probability)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "SCREAMING_SNAKE_CASE")]
pub enum AlertKind {
    FallDetected,
    PersonDown,
}

impl AlertKind {
    pub const fn name(self) -> &'static str {
        match self {
            AlertKind::FallDetected => "FALL_DETECTED",
            AlertKind::PersonDown => "PERSON_DOWN",
        }
    }
}

/// One alert.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FallAlert {
    pub kind: AlertKind,
    /// When it happened, seconds (stream time): the first scan of the fall for
    /// `FallDetected`, the moment `down_after_s` had been counted for `PersonDown` (time out
    /// of sight counted as `down_unseen_counts_s` says).
    pub event_time_s: f64,
    /// When the alert was raised (the scan that confirmed it), seconds.
    pub raised_at_s: f64,
    /// Since when the person has been down (`PersonDown`; for `FallDetected` the fall start).
    pub down_since_s: f64,
    /// The person's last seen position, map frame.
    pub position: DVec2,
    /// Probability of the evidence: for `FallDetected`, the mean of `falling_down` over the
    /// fall's scans, or, for a fall found by its descent (lying confirmed just after being
    /// off the floor, no fall run read), the summed on-floor classes of the confirming scan;
    /// for `PersonDown`, their mean over the visible scans since the person went down.
    pub confidence: f32,
}

/// One scan's input to the detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FallInput {
    pub stamp_s: f64,
    /// Where the person is (map frame); `None` when not seen in this scan, or while the
    /// classifier has too little history to publish an activity.
    pub position: Option<DVec2>,
    /// Class probabilities (class order); ignored when `position` is `None` (the model then
    /// sees an empty image, or has not seen enough).
    pub probabilities: [f32; Activity::COUNT],
    /// How far the person's points stretch along their main axis
    /// ([`MainAxisSpan::length`](crate::geometry::MainAxisSpan::length)); `None` when unknown.
    pub body_length_m: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Posture {
    Upright,
    OnFloor,
    GettingUp,
    Falling,
}

impl Posture {
    fn is_off_floor(self) -> bool {
        matches!(self, Posture::Upright | Posture::GettingUp)
    }
}

fn posture_of(activity: Activity) -> Posture {
    match activity {
        a if a.is_upright() => Posture::Upright,
        a if a.is_on_floor() => Posture::OnFloor,
        Activity::GettingUp => Posture::GettingUp,
        _ => Posture::Falling,
    }
}

/// When an alert was raised: its stamp, and the seen clock then (what re-arming counts
/// from).
#[derive(Debug, Clone, Copy)]
struct Disarmed {
    at_s: f64,
    seen_s: f64,
}

/// The alert state machine. Feed it every scan in time order.
#[derive(Debug, Clone)]
pub struct FallDetector {
    config: FallAlertConfig,
    last_stamp_s: Option<f64>,
    last_position: Option<DVec2>,
    /// Current run of scans read as falling_down.
    fall_run: Option<FallRun>,
    /// A fall run waiting for the person to be confirmed on the floor.
    pending_fall: Option<PendingFall>,
    /// Candidate posture, since when, how many consecutive scans (a hidden stretch longer
    /// than `glimpse_gap_s` breaks them).
    candidate: Option<(Posture, f64, u32)>,
    /// The body lengths known on the candidate's scans.
    candidate_lengths: Vec<f64>,
    /// p(lying_down) on the candidate's scans read as lying.
    candidate_lying: Vec<f64>,
    /// How surely the candidate's scans read it (`down_ends_min_probability`).
    candidate_reads: PostureReads,
    /// The last `confirm_scans` scans of the current run read as lying: what lands a fall
    /// run (`fall_lands_lying`).
    lying_run: VecDeque<LyingScan>,
    /// Confirmed posture and since when, on the seen clock.
    posture: Option<(Posture, f64)>,
    /// How surely the confirmed posture's scans, since it was first read, read it.
    posture_reads: PostureReads,
    /// The last visible scan classified upright while the confirmed posture was upright.
    last_upright_s: Option<f64>,
    /// How long the person had been seen upright by then (`upright_since` to
    /// `last_upright_s`).
    last_upright_for_s: f64,
    /// The scans read as falling since `last_upright_s`: a fall read in pieces.
    broken_fall_run: Option<BrokenFallRun>,
    /// The scans read as falling since the person was last read as getting up for
    /// `descent_getting_up_s`: a fall back down read in pieces.
    broken_fall_run_after_getting_up: Option<BrokenFallRun>,
    /// The same for upright or getting up (`descent_getting_up_s` into it): what a descent
    /// starts from.
    last_off_floor_s: Option<f64>,
    /// The last of those scans read as getting up: what a fall run may also start from
    /// (`fall_from_getting_up`).
    last_getting_up_s: Option<f64>,
    /// Consecutive visible scans read on the floor (crawling only with `crawling_shows_down`;
    /// with `down_found_in_view`, a hidden scan breaks them too).
    down_evidence_scans: u32,
    /// Whether that run has a scan read as lying.
    down_evidence_lying: bool,
    /// The body lengths on the last `down_lying_length_scans` scans read as lying since the
    /// person was last up again.
    lying_lengths: VecDeque<f64>,
    /// The last visible scan in a run of at least `confirm_scans` such readings.
    last_on_floor_s: Option<f64>,
    /// Whether a scan since then read the person upright or getting up.
    off_floor_since_on_floor: bool,
    down: Option<DownSpell>,
    /// Where the person was seen over the last `down_travel_within_s` while down, since the
    /// spell began or last restarted, oldest first.
    down_positions: VecDeque<(f64, DVec2)>,
    /// The last scan with the person seen (and classified).
    last_seen_s: Option<f64>,
    /// The stretches out of sight longer than `glimpse_gap_s` so far, in all: the seen
    /// clock (the stamp less this) stands still over them.
    hidden_s: f64,
    /// Since when, on the seen clock, the person has been upright without being confirmed
    /// on the floor or getting up in between (a `falling_down` misreading of a standing
    /// person does not break it): what re-arms the alerts.
    upright_since: Option<f64>,
    /// When each alert was last raised; `None` while armed.
    fall_disarmed_at: Option<Disarmed>,
    down_disarmed_at: Option<Disarmed>,
}

impl FallDetector {
    pub fn new(config: FallAlertConfig) -> Result<Self, FallConfigError> {
        config.validate()?;
        Ok(Self::fresh(config))
    }

    fn fresh(config: FallAlertConfig) -> Self {
        Self {
            config,
            last_stamp_s: None,
            last_position: None,
            fall_run: None,
            pending_fall: None,
            candidate: None,
            candidate_lengths: Vec::new(),
            candidate_lying: Vec::new(),
            candidate_reads: PostureReads::default(),
            lying_run: VecDeque::new(),
            posture: None,
            posture_reads: PostureReads::default(),
            last_upright_s: None,
            last_upright_for_s: 0.0,
            broken_fall_run: None,
            broken_fall_run_after_getting_up: None,
            last_off_floor_s: None,
            last_getting_up_s: None,
            down_evidence_scans: 0,
            down_evidence_lying: false,
            lying_lengths: VecDeque::new(),
            last_on_floor_s: None,
            off_floor_since_on_floor: false,
            down: None,
            down_positions: VecDeque::new(),
            last_seen_s: None,
            hidden_s: 0.0,
            upright_since: None,
            fall_disarmed_at: None,
            down_disarmed_at: None,
        }
    }

    pub fn config(&self) -> &FallAlertConfig {
        &self.config
    }

    /// Forgets everything: a new stream.
    pub fn reset(&mut self) {
        *self = Self::fresh(self.config);
    }

    /// Whether the person is currently considered down, and since when.
    pub fn down_since_s(&self) -> Option<f64> {
        self.down.map(|down| down.since_s)
    }

    /// Processes one scan; returns the alerts it raises (usually none, at most two).
    pub fn update(&mut self, input: &FallInput) -> Vec<FallAlert> {
        let mut alerts = Vec::new();
        let t = input.stamp_s;
        if !t.is_finite() {
            return alerts;
        }
        if self.last_stamp_s.is_some_and(|last| t < last) {
            self.reset();
        }
        // A scan before this one that did not see the person: a stretch out of sight.
        let missed_since_seen = self.last_stamp_s != self.last_seen_s;
        self.last_stamp_s = Some(t);

        let visible = input.position.filter(|p| p.is_finite());
        let probabilities_ok = input.probabilities.iter().all(|p| p.is_finite());
        if let (Some(position), true) = (visible, probabilities_ok) {
            self.last_position = Some(position);
            let unseen_s = self.unseen_beyond_count(t);
            if let Some(down) = self.down.as_mut() {
                down.uncounted_s += unseen_s;
            }
            if let Some(seen) = self
                .last_seen_s
                .filter(|seen| missed_since_seen && t - seen > self.config.glimpse_gap_s)
            {
                self.hidden_s += t - seen;
                self.candidate = None;
                self.fall_run = None;
                self.lying_run.clear();
            }
            self.last_seen_s = Some(t);
            let body_length_m = input.body_length_m.filter(|l| l.is_finite());
            self.observe(t, &input.probabilities, body_length_m, &mut alerts);
            self.restart_down_on_travel(t, position);
        } else if self.config.down_found_in_view {
            self.down_evidence_scans = 0;
            self.down_evidence_lying = false;
        }

        if let (Some(down), Some(position)) = (self.down, self.last_position) {
            // The stretch out of sight now running, if any, counts only so far too.
            let uncounted_s = down.uncounted_s + self.unseen_beyond_count(t);
            if self.down_disarmed_at.is_none()
                && t - down.since_s - uncounted_s >= self.config.down_after_s
                && !(self.config.down_waits_on_upright_glimpse && self.off_floor_since_on_floor)
                && self.seen_on_floor_lately(t)
            {
                self.down_disarmed_at = Some(self.disarmed_now(t));
                alerts.push(FallAlert {
                    kind: AlertKind::PersonDown,
                    event_time_s: down.since_s + uncounted_s + self.config.down_after_s,
                    raised_at_s: t,
                    down_since_s: down.since_s,
                    position,
                    confidence: down.confidence(),
                });
            }
        }
        alerts
    }

    /// `body_length_m` is finite where known.
    fn observe(
        &mut self,
        t: f64,
        probabilities: &[f32; Activity::COUNT],
        body_length_m: Option<f64>,
        alerts: &mut Vec<FallAlert>,
    ) {
        let (best, best_p) = Activity::most_likely(probabilities);
        let seen_now = self.seen_clock_s();
        let on_floor_p: f32 = Activity::ALL
            .into_iter()
            .filter(|a| a.is_on_floor())
            .map(|a| probabilities[a.index()])
            .sum();

        // Fall: consecutive scans read as falling_down, confidently on average.
        if best == Activity::FallingDown {
            for run in [
                &mut self.broken_fall_run,
                &mut self.broken_fall_run_after_getting_up,
            ] {
                run.get_or_insert(BrokenFallRun {
                    start_s: t,
                    scans: 0,
                    probability_sum: 0.0,
                })
                .add(best_p);
            }
            let min_scans = self.config.fall_min_scans as usize;
            let before_any_posture = self.posture.is_none();
            let run = self.fall_run.get_or_insert_with(|| FallRun {
                start_s: t,
                before_any_posture,
                recent: VecDeque::new(),
                counted: false,
            });
            push_keeping_last(&mut run.recent, min_scans, f64::from(best_p));
            let mean = run.recent.iter().sum::<f64>() / run.recent.len() as f64;
            // A pending run read ever more surely falling (`sure_fall_run_probability`).
            if run.counted
                && let Some(fall) = self.pending_fall.as_mut()
                && fall.start_s == run.start_s
            {
                fall.peak_confidence = fall.peak_confidence.max(mean);
                fall.last_scan_seen_s = seen_now;
            }
            if !run.counted
                && run.recent.len() == min_scans
                && mean >= f64::from(self.config.fall_probability)
            {
                run.counted = true;
                let (start, before_any_posture) = (run.start_s, run.before_any_posture);
                let from_upright = self.fell_from_upright(start, before_any_posture);
                let from_getting_up = self.fell_from_getting_up(start);
                if from_upright || from_getting_up {
                    let fall = PendingFall {
                        start_s: start,
                        counted_at_s: t,
                        last_scan_seen_s: seen_now,
                        confidence: mean,
                        peak_confidence: mean,
                        from_getting_up: !from_upright,
                        rearms: from_getting_up && self.got_up_since_fall_alert(),
                    };
                    if self.config.fall_then_floor_s > 0.0 {
                        self.pending_fall = Some(fall);
                    } else {
                        self.raise_pending_fall(t, fall, alerts);
                    }
                } else if self.config.down_restarts_on_fall_run
                    && let Some(down) = self.down.as_mut().filter(|d| d.since_s < start)
                {
                    *down = DownSpell::starting(start);
                    self.down_positions.retain(|&(at, _)| at >= start);
                }
            }
        } else {
            self.fall_run = None;
        }

        // Before the posture: a fall landing on this scan is dated from the fall, not a descent.
        self.check_lying_landing(t, best, best_p, body_length_m, alerts);

        // Posture with debouncing.
        let seen = posture_of(best);
        let (posture, since, n) = match self.candidate {
            Some((p, since, n)) if p == seen => (p, since, n + 1),
            _ => {
                self.candidate_lengths.clear();
                self.candidate_lying.clear();
                self.candidate_reads = PostureReads::default();
                (seen, t, 1)
            }
        };
        self.candidate = Some((posture, since, n));
        let sure = self.config.down_ends_min_probability;
        self.candidate_reads.add(best_p, sure);
        if n <= self.config.confirm_scans {
            if let Some(length) = body_length_m {
                self.candidate_lengths.push(length);
            }
            if best == Activity::LyingDown {
                self.candidate_lying.push(best_p as f64);
            }
        }
        // The candidate's scans lie in one stretch in sight: the seen clock then read `since`
        // less the stretches out of sight before it.
        let since_seen = since - self.hidden_s;
        if n >= self.config.confirm_scans && self.posture.map(|(p, _)| p) != Some(posture) {
            self.posture = Some((posture, since_seen));
            self.posture_reads = self.candidate_reads;
            match posture {
                Posture::OnFloor => {
                    self.upright_since = None;
                    if !self.config.fall_lands_lying
                        && let Some(fall) = self.pending_fall.take()
                        && since - fall.counted_at_s <= self.config.fall_then_floor_s
                    {
                        self.raise_pending_fall(t, fall, alerts);
                    }
                    self.start_down(since);
                    self.check_descent(t, since, best, on_floor_p, alerts);
                }
                Posture::Upright => {
                    self.upright_since.get_or_insert(since_seen);
                }
                Posture::GettingUp => {
                    self.upright_since = None;
                }
                Posture::Falling => {}
            }
        } else if self.posture.is_some_and(|(p, _)| p == seen) {
            self.posture_reads.add(best_p, sure);
        }
        if let Some(down) = self.down.as_mut() {
            down.on_floor_p_sum += on_floor_p as f64;
            down.scans += 1;
        }
        let confirmed = self.posture.map(|(p, _)| p);
        if seen == Posture::Upright && confirmed == Some(Posture::Upright) {
            self.last_upright_s = Some(t);
            self.last_upright_for_s = self.upright_since.map_or(0.0, |since| seen_now - since);
            self.broken_fall_run = None;
        }
        // Up again: confirmed getting up, or seen upright for `down_ends_upright_s`; after a
        // fall, surely and seen getting up for `down_ends_getting_up_s`.
        let after_fall = self.down.is_some_and(|down| down.after_fall);
        let getting_up_s = if after_fall {
            self.config.down_ends_getting_up_s
        } else {
            0.0
        };
        if let Some((posture, since)) = self.posture
            && seen == posture
            && (self.posture_reads.mostly_sure() || !after_fall)
            && match posture {
                Posture::GettingUp => seen_now - since >= getting_up_s,
                Posture::Upright => seen_now - since >= self.config.down_ends_upright_s,
                _ => false,
            }
        {
            self.down = None;
            self.lying_lengths.clear();
        }
        // Off the floor for a descent: upright once confirmed, getting up only after an
        // unbroken run of `descent_getting_up_s` (the candidate's).
        if seen.is_off_floor()
            && confirmed.is_some_and(Posture::is_off_floor)
            && (seen == Posture::Upright || t - since >= self.config.descent_getting_up_s)
        {
            self.last_off_floor_s = Some(t);
            if seen == Posture::GettingUp {
                self.last_getting_up_s = Some(t);
                self.broken_fall_run_after_getting_up = None;
            }
        }
        let shows_down =
            best.is_on_floor() && (self.config.crawling_shows_down || best != Activity::Crawling);
        if best == Activity::LyingDown
            && let Some(length) = body_length_m
        {
            let keep = self.config.down_lying_length_scans as usize;
            push_keeping_last(&mut self.lying_lengths, keep, length);
        }
        if shows_down {
            self.down_evidence_scans += 1;
            self.down_evidence_lying |= best == Activity::LyingDown;
        } else {
            self.down_evidence_scans = 0;
            self.down_evidence_lying = false;
        }
        if self.down_evidence_scans >= self.config.confirm_scans
            && (!self.down_evidence_lying
                || self.fall_disarmed_at.is_some()
                || self.down.is_some_and(|down| down.after_fall)
                || self.lying_stretches_as_a_body())
        {
            self.last_on_floor_s = Some(t);
            self.off_floor_since_on_floor = false;
        }
        if seen.is_off_floor() {
            self.off_floor_since_on_floor = true;
        }
        // A fall alerted, then a real attempt to get up, read so on every scan seen for
        // `rearm_getting_up_s` (the candidate's unbroken run): a fall from there is a new one.
        if posture == Posture::GettingUp
            && n >= self.config.confirm_scans
            && self.config.rearm_getting_up_s > 0.0
            && self.fall_disarmed_at.is_some_and(|at| {
                seen_now - since_seen.max(at.seen_s) >= self.config.rearm_getting_up_s
            })
        {
            self.fall_disarmed_at = None;
        }
        // Re-arm once seen upright long enough, counting only uprightness after the alert (an
        // alert raised while the person was still confirmed upright counts from the alert),
        // and only once the person is up again, not read upright with doubt: lying next would
        // otherwise be a new fall, from a person who never got up.
        if let Some(since) = self.upright_since
            && self.posture.is_some_and(|(p, _)| p == Posture::Upright)
        {
            let upright_long_enough = |disarmed_at: Option<Disarmed>| {
                disarmed_at.is_some_and(|at| {
                    seen_now - since.max(at.seen_s) >= self.config.rearm_upright_s
                })
            };
            if self.down.is_none() {
                if upright_long_enough(self.fall_disarmed_at) {
                    self.fall_disarmed_at = None;
                }
                if upright_long_enough(self.down_disarmed_at) {
                    self.down_disarmed_at = None;
                }
            }
            // Upright a while after a fall run: it was a stagger, or the fall is over.
            if self.pending_fall.is_some_and(|fall| {
                seen_now - since.max(fall.last_scan_seen_s) >= self.config.fall_cancel_upright_s
            }) {
                self.pending_fall = None;
            }
        }
    }

    /// Whether the latest scans read as lying stretch `down_lying_min_length_m` (their median;
    /// true when none has a length): a standing person read as lying is one or two legs.
    fn lying_stretches_as_a_body(&self) -> bool {
        let mut lengths: Vec<f64> = self.lying_lengths.iter().copied().collect();
        stretches_at_least(&mut lengths, self.config.down_lying_min_length_m)
    }

    /// Whether the scans that confirmed the floor posture show a body stretched on the floor
    /// that the classifier reads as lying without doubt (`descent_min_length_m`,
    /// `descent_min_probability`, each a median over those scans).
    fn candidate_looks_like_a_fallen_body(&mut self) -> bool {
        stretches_at_least(
            &mut self.candidate_lengths,
            self.config.descent_min_length_m,
        ) && surely_lying(
            &mut self.candidate_lying,
            self.config.descent_min_probability,
        )
    }

    /// With `fall_lands_lying`, raises a pending fall once `confirm_scans` consecutive scans
    /// read as lying without doubt begin within `fall_then_floor_s` of it; drops it when none
    /// can any more (without `fall_lands_lying`: when no floor posture that began within the
    /// window is being confirmed, as the posture's confirmation lands it). The scans slide
    /// along the lying run: a landing read as lying with doubt at first and surely a moment
    /// later is still a landing.
    fn check_lying_landing(
        &mut self,
        t: f64,
        best: Activity,
        best_p: f32,
        body_length_m: Option<f64>,
        alerts: &mut Vec<FallAlert>,
    ) {
        let confirm = self.config.confirm_scans as usize;
        if best == Activity::LyingDown {
            let scan = LyingScan {
                stamp_s: t,
                probability: f64::from(best_p),
                body_length_m,
            };
            let first_landing = self.lying_run.len() + 1 == confirm;
            push_keeping_last(&mut self.lying_run, confirm, scan);
            if self.lying_run.len() == confirm {
                if self.config.fall_lands_lying {
                    self.land_pending_fall(t, alerts);
                }
                if first_landing {
                    self.land_broken_fall_run(t, alerts);
                    self.land_broken_fall_run_after_getting_up(t, alerts);
                }
            }
        } else {
            self.lying_run.clear();
        }
        let window = self.config.fall_then_floor_s;
        let landing_since = if self.config.fall_lands_lying {
            self.lying_run.front().map(|scan| scan.stamp_s)
        } else {
            // A sitting landing begun in time was dropped here before its confirmation.
            self.floor_landing_since(t, best)
        };
        if let Some(run_at) = self.pending_fall.map(|fall| fall.counted_at_s)
            && t - run_at > window
            && landing_since.is_none_or(|since| since - run_at > window)
        {
            self.pending_fall = None;
        }
    }

    /// Since when the person has been read on the floor on every scan seen, this scan (`t`,
    /// read as `best`) included, while that floor posture is yet to be confirmed (on this
    /// scan at the latest): the start its confirmation will date the landing from.
    fn floor_landing_since(&self, t: f64, best: Activity) -> Option<f64> {
        if posture_of(best) != Posture::OnFloor {
            return None;
        }
        match self.candidate {
            Some((Posture::OnFloor, since, n)) => (n < self.config.confirm_scans).then_some(since),
            _ => Some(t),
        }
    }

    fn land_pending_fall(&mut self, t: f64, alerts: &mut Vec<FallAlert>) {
        let Some(fall) = self.pending_fall else {
            return;
        };
        let Some(since) = self.lying_run.front().map(|scan| scan.stamp_s) else {
            return;
        };
        // A run from getting up is no surer a fall than a descent from there, unless it was
        // read surely falling.
        let sure = self.config.sure_fall_run_probability;
        let surely_falling = sure > 0.0 && fall.peak_confidence >= sure;
        let min_probability = if fall.from_getting_up && !surely_falling {
            self.config.descent_min_probability
        } else {
            self.config.landing_min_probability
        };
        if since - fall.counted_at_s <= self.config.fall_then_floor_s
            && self.lying_run_is_a_landing(min_probability, self.config.landing_min_length_m)
        {
            self.pending_fall = None;
            self.raise_pending_fall(t, fall, alerts);
        }
    }

    /// With `broken_fall_run_scans`, raises the fall read in pieces since the person was last
    /// upright once the first `confirm_scans` scans of a lying run are a landing (as
    /// [`Self::land_pending_fall`]'s) that began within `descent_max_s` of being upright.
    /// Only the first: a body on the floor read with doubt for a second or more, and in
    /// part, lay there all along (seed 7 episode 41: misread standing for 2 s, then falling
    /// on 4 scans, then lying that stretched 0.8 m only 1.25 s on).
    fn land_broken_fall_run(&mut self, t: f64, alerts: &mut Vec<FallAlert>) {
        if self.fall_disarmed_at.is_some()
            || self.last_upright_for_s < self.config.broken_fall_run_upright_s
        {
            return;
        }
        if let Some(run) = self.broken_run_landing(
            self.broken_fall_run,
            self.last_upright_s,
            self.config.landing_min_probability,
        ) {
            self.broken_fall_run = None;
            self.raise_fall(t, run.start_s, run.mean_probability(), alerts);
        }
    }

    /// The same for a fall back down read in pieces since the person was last read as getting
    /// up (`descent_getting_up_s` into it), landing as surely as a descent's and re-arming the
    /// alert as a run from getting up does (`fall_from_getting_up`).
    fn land_broken_fall_run_after_getting_up(&mut self, t: f64, alerts: &mut Vec<FallAlert>) {
        let rearms = self.got_up_since_fall_alert();
        let upright_since_getting_up = self
            .last_upright_s
            .zip(self.last_getting_up_s)
            .is_some_and(|(upright, getting_up)| upright > getting_up);
        if !self.config.fall_from_getting_up
            || (self.fall_disarmed_at.is_some() && !rearms)
            || upright_since_getting_up
        {
            return;
        }
        if let Some(run) = self.broken_run_landing(
            self.broken_fall_run_after_getting_up,
            self.last_getting_up_s,
            self.config.descent_min_probability,
        ) {
            self.broken_fall_run_after_getting_up = None;
            if rearms {
                self.fall_disarmed_at = None;
            }
            self.raise_fall(t, run.start_s, run.mean_probability(), alerts);
        }
    }

    /// `run` when it has `broken_fall_run_scans`, no run is pending, and the lying run is a
    /// landing at `min_probability` that began within `descent_max_s` of `off_floor_at`.
    fn broken_run_landing(
        &self,
        run: Option<BrokenFallRun>,
        off_floor_at: Option<f64>,
        min_probability: f64,
    ) -> Option<BrokenFallRun> {
        let (run, off_floor_at) = (run?, off_floor_at?);
        let lying_since = self.lying_run.front()?.stamp_s;
        let min_scans = self.config.broken_fall_run_scans;
        (min_scans > 0
            && run.scans >= min_scans
            && self.pending_fall.is_none()
            && lying_since - off_floor_at <= self.config.descent_max_s
            && self.lying_run_is_a_landing(min_probability, self.config.descent_min_length_m))
        .then_some(run)
    }

    /// Whether the lying run (the last `confirm_scans` scans, all read as lying) is a
    /// landing: a median p(lying_down) of at least `min_probability`, and the person's
    /// points stretching a median `min_length_m`.
    fn lying_run_is_a_landing(&self, min_probability: f64, min_length_m: f64) -> bool {
        let mut probabilities: Vec<f64> = self.lying_run.iter().map(|s| s.probability).collect();
        let mut lengths: Vec<f64> = self
            .lying_run
            .iter()
            .filter_map(|s| s.body_length_m)
            .collect();
        surely_lying(&mut probabilities, min_probability)
            && stretches_at_least(&mut lengths, min_length_m)
    }

    fn raise_pending_fall(&mut self, t: f64, fall: PendingFall, alerts: &mut Vec<FallAlert>) {
        if fall.rearms {
            self.fall_disarmed_at = None;
        }
        self.raise_fall(t, fall.start_s, fall.confidence, alerts);
    }

    /// `FallDetected` for a `falling_down` run that began at `start` (once per incident); the
    /// person is down from then.
    fn raise_fall(&mut self, t: f64, start: f64, confidence: f64, alerts: &mut Vec<FallAlert>) {
        self.start_down(start);
        self.mark_fall_in_spell();
        if self.fall_disarmed_at.is_none() {
            self.fall_disarmed_at = Some(self.disarmed_now(t));
            alerts.push(FallAlert {
                kind: AlertKind::FallDetected,
                event_time_s: start,
                raised_at_s: t,
                down_since_s: start,
                position: self.last_position.unwrap_or(DVec2::ZERO),
                confidence: confidence as f32,
            });
        }
    }

    /// Whether a fall starting at `start` follows being upright closely enough, or began
    /// before any posture was confirmed (`fall_on_first_sight`).
    fn fell_from_upright(&self, start: f64, before_any_posture: bool) -> bool {
        let limit = self.config.fall_from_upright_s;
        limit <= 0.0
            || self.last_upright_s.is_some_and(|at| start - at <= limit)
            || (self.config.fall_on_first_sight && before_any_posture)
    }

    /// Whether a fall starting at `start` follows getting up as closely as
    /// `fall_from_upright_s` asks of being upright (`fall_from_getting_up`).
    fn fell_from_getting_up(&self, start: f64) -> bool {
        self.config.fall_from_getting_up
            && self
                .last_getting_up_s
                .is_some_and(|at| start - at <= self.config.fall_from_upright_s)
    }

    /// Whether `FallDetected` was raised and the person read as getting up after it.
    fn got_up_since_fall_alert(&self) -> bool {
        self.fall_disarmed_at
            .zip(self.last_getting_up_s)
            .is_some_and(|(alerted, getting_up)| getting_up > alerted.at_s)
    }

    /// Lying confirmed soon after the person was last off the floor, by a body that looks
    /// fallen: a fall, seen or not.
    fn check_descent(
        &mut self,
        t: f64,
        lying_since: f64,
        best: Activity,
        on_floor_p: f32,
        alerts: &mut Vec<FallAlert>,
    ) {
        let Some(off_floor_at) = self.last_off_floor_s else {
            return;
        };
        if best != Activity::LyingDown
            || self.fall_disarmed_at.is_some()
            || self.config.descent_max_s <= 0.0
            || lying_since - off_floor_at > self.config.descent_max_s
            || !self.candidate_looks_like_a_fallen_body()
        {
            return;
        }
        self.mark_fall_in_spell();
        self.fall_disarmed_at = Some(self.disarmed_now(t));
        // A run waiting for a landing waits for this one: when it lands it still dates the
        // incident, but this alert is its alert, not a re-armed one a scan later.
        if let Some(fall) = self.pending_fall.as_mut() {
            fall.rearms = false;
        }
        alerts.push(FallAlert {
            kind: AlertKind::FallDetected,
            event_time_s: off_floor_at,
            raised_at_s: t,
            down_since_s: lying_since,
            position: self.last_position.unwrap_or(DVec2::ZERO),
            confidence: on_floor_p,
        });
    }

    /// The spell the person is down in follows a recognised fall: proof of the floor, and
    /// being up again needs surer readings (`down_ends_min_probability`).
    fn mark_fall_in_spell(&mut self) {
        if let Some(down) = self.down.as_mut() {
            down.after_fall = true;
        }
    }

    /// Whether the person was last confirmed on the floor recently enough to be alerted as
    /// down (`down_seen_within_s`).
    fn seen_on_floor_lately(&self, t: f64) -> bool {
        let limit = self.config.down_seen_within_s;
        limit <= 0.0 || self.last_on_floor_s.is_some_and(|at| t - at <= limit)
    }

    /// The person is down since `since`, or since earlier if already down: a fall raised
    /// on a landing confirmed after the floor posture dates the incident from the fall.
    fn start_down(&mut self, since: f64) {
        match self.down.as_mut() {
            Some(down) => down.since_s = down.since_s.min(since),
            None => self.down = Some(DownSpell::starting(since)),
        }
    }

    /// A person down who is seen at `position` at least `down_travel_m` from where they were
    /// seen within `down_travel_within_s` has been up: their spell starts again at `t`.
    /// Positions from before the spell began are dropped: a fall itself carries the body on.
    fn restart_down_on_travel(&mut self, t: f64, position: DVec2) {
        let travel = self.config.down_travel_m;
        let Some(down) = self.down.as_mut().filter(|_| travel > 0.0) else {
            self.down_positions.clear();
            return;
        };
        let window = self.config.down_travel_within_s;
        while self
            .down_positions
            .front()
            .is_some_and(|&(at, _)| t - at > window)
        {
            self.down_positions.pop_front();
        }
        if self
            .down_positions
            .iter()
            .any(|&(_, p)| p.distance(position) >= travel)
        {
            *down = DownSpell::starting(t);
            self.down_positions.clear();
        }
        self.down_positions.push_back((t, position));
    }

    /// The seen clock: the stamp of the last scan the person was seen on, less the stretches
    /// out of sight longer than `glimpse_gap_s` before it. It stands still while the person
    /// is out of sight, so what it measures is time seen (glimpse gaps included).
    fn seen_clock_s(&self) -> f64 {
        self.last_seen_s.map_or(0.0, |seen| seen - self.hidden_s)
    }

    /// An alert raised at `t`.
    fn disarmed_now(&self, t: f64) -> Disarmed {
        Disarmed {
            at_s: t,
            seen_s: self.seen_clock_s(),
        }
    }

    /// How much of the time out of sight from the last scan the person was seen on (or
    /// since they are down, if later) to `t` exceeds `down_unseen_counts_s`.
    fn unseen_beyond_count(&self, t: f64) -> f64 {
        let cap = self.config.down_unseen_counts_s;
        match (self.last_seen_s, self.down) {
            (Some(seen), Some(down)) if cap > 0.0 => (t - seen.max(down.since_s) - cap).max(0.0),
            _ => 0.0,
        }
    }
}

/// A run of consecutive scans read as falling_down.
#[derive(Debug, Clone)]
struct FallRun {
    start_s: f64,
    /// Whether it began before any posture of the person was confirmed (`fall_on_first_sight`).
    before_any_posture: bool,
    /// p(falling_down) on its last `fall_min_scans` scans.
    recent: VecDeque<f64>,
    /// Whether it has reached `fall_probability` on average (counted once).
    counted: bool,
}

/// The scans read as `falling_down` since the person was last read upright, in a row or not.
#[derive(Debug, Clone, Copy)]
struct BrokenFallRun {
    start_s: f64,
    scans: u32,
    probability_sum: f64,
}

impl BrokenFallRun {
    fn add(&mut self, probability: f32) {
        self.scans += 1;
        self.probability_sum += f64::from(probability);
    }

    fn mean_probability(&self) -> f64 {
        self.probability_sum / f64::from(self.scans.max(1))
    }
}

/// How many of the scans read as one posture read it with at least
/// `down_ends_min_probability`.
#[derive(Debug, Clone, Copy, Default)]
struct PostureReads {
    scans: u32,
    sure: u32,
}

impl PostureReads {
    fn add(&mut self, probability: f32, sure: f64) {
        self.scans = self.scans.saturating_add(1);
        self.sure = self
            .sure
            .saturating_add(u32::from(f64::from(probability) >= sure));
    }

    /// At least half of them: their median reaches it.
    fn mostly_sure(self) -> bool {
        2 * u64::from(self.sure) >= u64::from(self.scans)
    }
}

/// The incident the person is down in.
#[derive(Debug, Clone, Copy)]
struct DownSpell {
    since_s: f64,
    /// Summed on-floor probability over the scans since: the alert's confidence.
    on_floor_p_sum: f64,
    scans: u32,
    /// Time out of sight beyond `down_unseen_counts_s` a stretch: not counted as down.
    uncounted_s: f64,
    /// Whether a fall was recognised in it: the floor needs no other proof then.
    after_fall: bool,
}

impl DownSpell {
    fn starting(since_s: f64) -> Self {
        Self {
            since_s,
            on_floor_p_sum: 0.0,
            scans: 0,
            uncounted_s: 0.0,
            after_fall: false,
        }
    }

    fn confidence(&self) -> f32 {
        if self.scans > 0 {
            (self.on_floor_p_sum / f64::from(self.scans)) as f32
        } else {
            0.0
        }
    }
}

/// Whether the median p(lying_down) of scans read as lying reaches `min_p` (always when
/// `min_p` is 0, never without such scans otherwise).
fn surely_lying(lying_probabilities: &mut [f64], min_p: f64) -> bool {
    min_p <= 0.0 || upper_median(lying_probabilities).is_some_and(|p| p >= min_p)
}

/// Whether the median of the known body lengths reaches `min_m` (always when `min_m` is 0 or
/// no length is known).
fn stretches_at_least(lengths_m: &mut [f64], min_m: f64) -> bool {
    min_m <= 0.0 || upper_median(lengths_m).is_none_or(|l| l >= min_m)
}

/// Appends `value`, keeping the last `keep` values: the sliding windows over runs of scans.
fn push_keeping_last<T>(window: &mut VecDeque<T>, keep: usize, value: T) {
    while window.len() >= keep.max(1) {
        window.pop_front();
    }
    window.push_back(value);
}

/// A counted `falling_down` run waiting for its landing.
#[derive(Debug, Clone, Copy)]
struct PendingFall {
    start_s: f64,
    /// When it reached `fall_min_scans`.
    counted_at_s: f64,
    /// Its latest scan read as falling, on the seen clock: time upright counts from here,
    /// not from the count, so a run that counts early is not dropped while the person is
    /// still falling.
    last_scan_seen_s: f64,
    /// Its mean probability when counted.
    confidence: f64,
    /// The highest mean over `fall_min_scans` scans it has reached since.
    peak_confidence: f64,
    /// Whether it began after getting up, not after being upright (`fall_from_getting_up`):
    /// its landing must then be as sure of lying as a descent's.
    from_getting_up: bool,
    /// Whether its landing re-arms `FallDetected`: it began after getting up again since the
    /// alert.
    rearms: bool,
}

/// A scan read as lying.
#[derive(Debug, Clone, Copy)]
struct LyingScan {
    stamp_s: f64,
    /// p(lying_down).
    probability: f64,
    body_length_m: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use Activity::*;

    const DT: f64 = 0.05; // 20 Hz

    fn one_hot(a: Activity, p: f32) -> [f32; 9] {
        let mut probs = [(1.0 - p) / 8.0; 9];
        probs[a.index()] = p;
        probs
    }

    /// The classifier's probability of the scripted activity: a confident reading.
    const SURE: f32 = 0.95;

    /// Runs a script of (activity, seconds, visible) segments at 20 Hz; returns the alerts.
    fn run(detector: &mut FallDetector, script: &[(Activity, f64, bool)]) -> Vec<FallAlert> {
        let script: Vec<_> = script
            .iter()
            .map(|&(a, s, v)| (a, s, v, None, SURE))
            .collect();
        run_scans(detector, &script)
    }

    /// [`run`] with the person always seen, at a body length per segment.
    fn run_with_lengths(
        detector: &mut FallDetector,
        script: &[(Activity, f64, f64)],
    ) -> Vec<FallAlert> {
        let script: Vec<_> = script
            .iter()
            .map(|&(a, s, length)| (a, s, true, Some(length), SURE))
            .collect();
        run_scans(detector, &script)
    }

    /// Segments of (activity, seconds, visible, body length, the activity's probability).
    fn run_scans(
        detector: &mut FallDetector,
        script: &[(Activity, f64, bool, Option<f64>, f32)],
    ) -> Vec<FallAlert> {
        let mut t = 0.0;
        let mut alerts = Vec::new();
        for &(activity, seconds, visible, body_length_m, p) in script {
            let scans = (seconds / DT).round() as usize;
            for _ in 0..scans {
                alerts.extend(detector.update(&FallInput {
                    stamp_s: t,
                    position: visible.then_some(DVec2::new(1.0, 2.0)),
                    probabilities: one_hot(activity, p),
                    body_length_m,
                }));
                t += DT;
            }
        }
        alerts
    }

    fn kinds(alerts: &[FallAlert]) -> Vec<AlertKind> {
        alerts.iter().map(|a| a.kind).collect()
    }

    fn detector() -> FallDetector {
        FallDetector::new(FallAlertConfig::default()).unwrap()
    }

    /// A detector with the defaults but for what `change` sets.
    fn detector_with(change: impl FnOnce(&mut FallAlertConfig)) -> FallDetector {
        let mut config = FallAlertConfig::default();
        change(&mut config);
        FallDetector::new(config).unwrap()
    }

    /// Tests of `PersonDown` alone script people lying down from standing in no time, which
    /// the descent rule takes for a fall.
    fn without_descent() -> FallDetector {
        detector_with(|c| c.descent_max_s = 0.0)
    }

    #[test]
    fn lying_soon_after_being_upright_is_a_fall_even_unseen_as_falling() {
        let mut d = detector();
        // The classifier never says falling_down: walking, then lying (after a second it
        // could not make sense of), then staying down.
        let alerts = run(
            &mut d,
            &[
                (Walking, 5.0, true),
                (SittingOnFloor, 0.2, true),
                (LyingDown, 30.0, true),
            ],
        );
        assert_eq!(
            kinds(&alerts),
            [AlertKind::FallDetected, AlertKind::PersonDown]
        );
        let fall = alerts[0];
        assert!((fall.event_time_s - 4.95).abs() < 1e-9, "{fall:?}");
        // Lying confirmed after confirm_scans: 0.45 s after the person was last upright.
        assert!(fall.raised_at_s - fall.event_time_s < 0.5, "{fall:?}");
    }

    #[test]
    fn sitting_down_or_lying_down_slowly_is_not_a_fall() {
        let mut d = detector();
        let sit = run(
            &mut d,
            &[
                (Walking, 5.0, true),
                (SittingOnFloor, 5.0, true),
                (Walking, 5.0, true),
            ],
        );
        assert!(sit.is_empty(), "{sit:?}");
        let mut d = detector();
        let slow = run(
            &mut d,
            &[
                (Walking, 5.0, true),
                (SittingOnFloor, 4.0, true),
                (LyingDown, 5.0, true),
                (GettingUp, 2.0, true),
                (Walking, 5.0, true),
            ],
        );
        assert!(slow.is_empty(), "{slow:?}");
    }

    #[test]
    fn a_fall_seen_from_the_first_scan_counts_unless_fall_on_first_sight_is_off() {
        // The person is found falling (hidden before), then lies: nobody saw them upright.
        let script = [
            (Standing, 2.0, false),
            (FallingDown, 0.6, true),
            (LyingDown, 3.0, true),
        ];
        let off = run(
            &mut detector_with(|c| c.fall_on_first_sight = false),
            &script,
        );
        assert!(off.is_empty(), "{off:?}");
        let on = run(
            &mut detector_with(|c| c.fall_on_first_sight = true),
            &script,
        );
        assert_eq!(kinds(&on), [AlertKind::FallDetected]);
        assert!((on[0].event_time_s - 2.0).abs() < 1e-9, "{:?}", on[0]);
        // A run that begins later, after the person was first seen on the floor, does not.
        let later = run(
            &mut detector(),
            &[
                (SittingOnFloor, 2.0, true),
                (FallingDown, 0.6, true),
                (LyingDown, 3.0, true),
            ],
        );
        assert!(later.is_empty(), "{later:?}");
    }

    #[test]
    fn a_fall_counts_as_first_sight_until_a_posture_is_confirmed() {
        // The model's first readings of a stream: getting up on a few scans, too few to
        // confirm it, then falling and lying.
        let unconfirmed_first = [
            (GettingUp, 0.15, true),
            (FallingDown, 0.6, true),
            (LyingDown, 3.0, true),
        ];
        let on = run(&mut detector(), &unconfirmed_first);
        assert_eq!(kinds(&on), [AlertKind::FallDetected]);
        assert!((on[0].event_time_s - 0.15).abs() < 1e-6, "{:?}", on[0]);
        let off = run(
            &mut detector_with(|c| c.fall_on_first_sight = false),
            &unconfirmed_first,
        );
        assert!(off.is_empty(), "{off:?}");
        // Getting up confirmed first: the person's posture is known, and getting up for
        // less than `descent_getting_up_s` starts no fall.
        let confirmed_first = run(
            &mut detector(),
            &[
                (GettingUp, 0.3, true),
                (FallingDown, 0.6, true),
                (LyingDown, 3.0, true),
            ],
        );
        assert!(confirmed_first.is_empty(), "{confirmed_first:?}");
    }

    #[test]
    fn moves_on_the_floor_misread_for_a_moment_are_not_falls() {
        // Sitting, three scans of getting up and two of walking (neither confirmed), then
        // lying: never off the floor since the sitting, so no descent.
        let mut d = detector();
        let flicker = run(
            &mut d,
            &[
                (Walking, 5.0, true),
                (SittingOnFloor, 5.0, true),
                (GettingUp, 0.15, true),
                (Walking, 0.1, true),
                (LyingDown, 5.0, true),
            ],
        );
        assert!(flicker.is_empty(), "{flicker:?}");
        // Crawling, then getting up taken for a fall: nobody falls from the floor.
        let mut d = detector();
        let from_floor = run(
            &mut d,
            &[
                (Walking, 5.0, true),
                (Crawling, 5.0, true),
                (FallingDown, 0.5, true),
                (GettingUp, 1.0, true),
                (Walking, 5.0, true),
            ],
        );
        assert!(from_floor.is_empty(), "{from_floor:?}");
        // Without the requirement, the same misreading is an alert.
        let mut d = detector_with(|c| {
            c.fall_from_upright_s = 0.0;
            c.fall_lands_lying = false;
        });
        let loose = run(
            &mut d,
            &[
                (Walking, 5.0, true),
                (Crawling, 5.0, true),
                (FallingDown, 0.5, true),
                (Crawling, 1.0, true),
            ],
        );
        assert_eq!(kinds(&loose), [AlertKind::FallDetected]);
    }

    #[test]
    fn a_stagger_read_as_falling_that_ends_upright_is_not_a_fall() {
        let script = [
            (Walking, 5.0, true),
            (FallingDown, 0.6, true),
            (Walking, 5.0, true),
        ];
        let stagger = run(&mut detector(), &script);
        assert!(stagger.is_empty(), "{stagger:?}");
        // Raised at the run itself, it is an alert, on the run's fifth scan.
        let at_run = run(&mut detector_with(|c| c.fall_then_floor_s = 0.0), &script);
        assert_eq!(kinds(&at_run), [AlertKind::FallDetected]);
        assert!((at_run[0].raised_at_s - 5.2).abs() < 1e-6, "{at_run:?}");
    }

    #[test]
    fn an_alert_raised_while_still_upright_rearms_after_being_upright_past_it() {
        // Alerted at the run (`fall_then_floor_s: 0`), a stagger leaves the person upright
        // throughout: the next fall a minute later is alerted again.
        let mut d = detector_with(|c| c.fall_then_floor_s = 0.0);
        let script = [
            (Walking, 5.0, true),
            (FallingDown, 0.6, true),
            (Walking, 60.0, true),
            (FallingDown, 1.0, true),
            (LyingDown, 30.0, true),
        ];
        let alerts = run(&mut d, &script);
        assert_eq!(
            kinds(&alerts),
            [
                AlertKind::FallDetected,
                AlertKind::FallDetected,
                AlertKind::PersonDown
            ],
            "{alerts:?}"
        );
        // PERSON_DOWN raised as walking begins, the posture not yet upright: re-armed once
        // upright past the alert, so sitting down for long again is alerted again.
        let mut d = detector_with(|c| {
            c.down_waits_on_upright_glimpse = false;
            c.descent_max_s = 0.0;
        });
        let due = d.config.down_after_s;
        let script = [
            (SittingOnFloor, due - 0.05, true),
            (Walking, 30.0, true),
            (SittingOnFloor, due + 5.0, true),
        ];
        let alerts = run(&mut d, &script);
        assert_eq!(
            kinds(&alerts),
            [AlertKind::PersonDown, AlertKind::PersonDown],
            "{alerts:?}"
        );
    }

    #[test]
    fn a_stagger_alerted_at_its_run_does_not_leave_the_person_down() {
        // A run shorter than `confirm_scans` never becomes a posture; the person read
        // upright again is not down, so sitting a minute later is not PERSON_DOWN at once.
        let mut d = detector_with(|c| {
            c.fall_then_floor_s = 0.0;
            c.fall_min_scans = 3;
        });
        let script = [
            (Walking, 5.0, true),
            (FallingDown, 0.2, true),
            (Walking, 60.0, true),
            (SittingOnFloor, 1.0, true),
        ];
        let alerts = run(&mut d, &script);
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected], "{alerts:?}");
    }

    #[test]
    fn a_stop_read_as_falling_then_sitting_down_is_not_a_fall() {
        let script = [
            (Walking, 5.0, true),
            (FallingDown, 0.7, true),
            (Standing, 1.0, true),
            (SittingOnFloor, 5.0, true),
        ];
        let sat = run(&mut detector(), &script);
        assert!(sat.is_empty(), "{sat:?}");
        // With the run kept through the second upright, only landing lying counts.
        let keeping_the_run = |lands_lying| {
            detector_with(|c| {
                c.fall_lands_lying = lands_lying;
                c.fall_cancel_upright_s = 1.5;
            })
        };
        let sat = run(&mut keeping_the_run(true), &script);
        assert!(sat.is_empty(), "{sat:?}");
        let sat = run(&mut keeping_the_run(false), &script);
        assert_eq!(kinds(&sat), [AlertKind::FallDetected]);
        // Landing lying, but with doubt (p 0.6, a fallen body is read at 0.94-1.00): no fall.
        let unsure = [
            (Walking, 5.0, true, None, SURE),
            (FallingDown, 0.7, true, None, SURE),
            (LyingDown, 0.25, true, None, 0.6),
            (SittingOnFloor, 5.0, true, None, SURE),
        ];
        let alerts = run_scans(&mut without_descent(), &unsure);
        assert!(alerts.is_empty(), "{alerts:?}");
    }

    #[test]
    fn without_landing_lying_a_sitting_landing_begun_in_time_is_a_fall() {
        // Standing, read as falling (counted at 2.2 s), hidden, then found sitting on the
        // floor `found_after_s` after the run counted; confirmed 5 scans (0.2 s) later.
        let landing = |lands_lying, found_after_s: f64| {
            let script = [
                (Standing, 2.0, true),
                (FallingDown, 0.25, true),
                (Standing, found_after_s - DT, false),
                (SittingOnFloor, 2.0, true),
            ];
            run(
                &mut detector_with(|c| c.fall_lands_lying = lands_lying),
                &script,
            )
        };
        // Begun within `fall_then_floor_s` (3 s), confirmed after it: used to be dropped
        // before its confirmation, as a lying landing is not.
        let alerts = landing(false, 2.9);
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
        assert!((alerts[0].event_time_s - 2.0).abs() < 1e-9, "{alerts:?}");
        assert!((alerts[0].raised_at_s - 5.3).abs() < 1e-6, "{alerts:?}");
        // Begun after it: no fall; and landing lying (the default) sitting is none.
        assert!(landing(false, 3.05).is_empty());
        assert!(landing(true, 2.9).is_empty());
    }

    #[test]
    fn without_landing_lying_a_fall_run_on_a_person_already_down_is_dropped_in_time() {
        // Confirmed sitting on the floor, then a run of 3 scans read as falling (not enough
        // to confirm a posture; 2.6 s after being upright), then sitting on: no floor posture
        // is confirmed anew, so the run is dropped once `fall_then_floor_s` is over.
        let pending_after = |sitting_s| {
            let mut d = detector_with(|c| {
                c.fall_lands_lying = false;
                c.fall_min_scans = 3;
            });
            let script = [
                (Standing, 2.0, true),
                (SittingOnFloor, 2.5, true),
                (FallingDown, 0.15, true),
                (SittingOnFloor, sitting_s, true),
            ];
            let alerts = run(&mut d, &script);
            assert!(alerts.is_empty(), "{alerts:?}");
            d.pending_fall.is_some()
        };
        // Counted at 4.6 s: pending up to 7.6 s (the last scan at 7.5 s), not after.
        assert!(pending_after(2.9));
        assert!(!pending_after(3.1));
    }

    #[test]
    fn a_fall_run_lands_on_less_certain_lying_than_a_descent_needs() {
        let fall_then_lying = |p| {
            [
                (Walking, 5.0, true, None, SURE),
                (FallingDown, 0.7, true, None, SURE),
                (LyingDown, 3.0, true, Some(1.5), p),
            ]
        };
        let landing_and_descent = |landing, descent| {
            detector_with(|c| {
                c.landing_min_probability = landing;
                c.descent_min_probability = descent;
            })
        };
        // Lying read at 0.85: enough to land the run, not enough for a descent alone.
        let alerts = run_scans(&mut landing_and_descent(0.8, 0.9), &fall_then_lying(0.85));
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
        assert!((alerts[0].event_time_s - 5.0).abs() < 1e-9, "{alerts:?}");
        let alerts = run_scans(&mut landing_and_descent(0.9, 0.9), &fall_then_lying(0.85));
        assert!(alerts.is_empty(), "{alerts:?}");
        // Without the run, the same lying is no descent at 0.9, one at 0.8.
        let descent_only = [
            (Walking, 5.0, true, None, SURE),
            (LyingDown, 3.0, true, Some(1.5), 0.85),
        ];
        let alerts = run_scans(&mut landing_and_descent(0.8, 0.9), &descent_only);
        assert!(alerts.is_empty(), "{alerts:?}");
        let alerts = run_scans(&mut landing_and_descent(0.8, 0.8), &descent_only);
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
    }

    #[test]
    fn a_landing_read_as_sitting_at_first_is_a_fall_once_read_lying_in_time() {
        // The run reaches 8 scans at 5.35 s; the landing is read as sitting from 5.6 s.
        let landing = |sitting_s| {
            let mut d = detector();
            let script = [
                (Walking, 5.0, true),
                (FallingDown, 0.6, true),
                (SittingOnFloor, sitting_s, true),
                (LyingDown, 2.0, true),
            ];
            (run(&mut d, &script), d.down_since_s())
        };
        // Lying from 8.1 s, 2.75 s after the run: the fall, dated from its start.
        let (alerts, down_since) = landing(2.5);
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
        assert!((alerts[0].event_time_s - 5.0).abs() < 1e-9, "{alerts:?}");
        assert!((alerts[0].raised_at_s - 8.3).abs() < 1e-6, "{alerts:?}");
        assert!(
            down_since.is_some_and(|s| (s - 5.0).abs() < 1e-9),
            "{down_since:?}"
        );
        // Lying from 8.6 s: too late.
        let (alerts, _) = landing(3.0);
        assert!(alerts.is_empty(), "{alerts:?}");
    }

    /// Walking, then a confident `falling_down` run (from 5.0 s), then `after`; descents off,
    /// so only the run can make the fall alert.
    fn alerts_after_a_fall_run(after: &[(Activity, f64, bool)]) -> Vec<FallAlert> {
        run_after_a_fall_run(&mut without_descent(), after)
    }

    /// [`alerts_after_a_fall_run`] on `detector`.
    fn run_after_a_fall_run(
        detector: &mut FallDetector,
        after: &[(Activity, f64, bool)],
    ) -> Vec<FallAlert> {
        let walk_and_run = [(Walking, 5.0, true), (FallingDown, 0.6, true)];
        run(detector, &[&walk_and_run, after].concat())
    }

    #[test]
    fn a_fall_run_must_reach_the_floor_in_time() {
        // Read as falling, hidden, then found lying 4 s later: too late for the run (3 s);
        // the person is still found down (PERSON_DOWN).
        let alerts = alerts_after_a_fall_run(&[(LyingDown, 4.0, false), (LyingDown, 20.0, true)]);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
    }

    #[test]
    fn lying_read_with_doubt_at_first_then_surely_lands_a_fall_run() {
        // After the run, lying is read at 0.6 for `doubt_s`, then at 0.95: the last
        // `confirm_scans` scans slide along the lying run, so the sure ones land it.
        let landing = |doubt_s: f64| {
            run_scans(
                &mut without_descent(),
                &[
                    (Walking, 5.0, true, None, SURE),
                    (FallingDown, 0.6, true, None, SURE),
                    (LyingDown, doubt_s, true, None, 0.6),
                    (LyingDown, 1.0, true, None, SURE),
                ],
            )
        };
        let alerts = landing(0.2);
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
        // Landed once three of the last five scans read surely: the seventh lying scan.
        assert!((alerts[0].raised_at_s - 5.9).abs() < 1e-6, "{alerts:?}");
        // Sure lying that begins after `fall_then_floor_s` lands nothing.
        let alerts = landing(3.2);
        assert!(alerts.is_empty(), "{alerts:?}");
    }

    #[test]
    fn a_fall_run_counts_on_its_mean_probability() {
        // falling_down the top class on every scan of the run, at p alternating between two
        // values: the run counts once its last `fall_min_scans` scans average 0.7.
        let fall_run = |low: f32, high: f32| {
            let mut script = vec![(Walking, 5.0, true, None, SURE)];
            for i in 0..12 {
                let p = if i % 2 == 0 { low } else { high };
                script.push((FallingDown, DT, true, None, p));
            }
            script.push((LyingDown, 2.0, true, None, SURE));
            run_scans(&mut without_descent(), &script)
        };
        // Five scans, three of them high: 0.77.
        let alerts = fall_run(0.5, 0.95);
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
        assert!((alerts[0].event_time_s - 5.0).abs() < 1e-6, "{alerts:?}");
        assert!((alerts[0].confidence - 0.77).abs() < 1e-6, "{alerts:?}");
        // 0.68 at best.
        let alerts = fall_run(0.5, 0.8);
        assert!(alerts.is_empty(), "{alerts:?}");
    }

    #[test]
    fn a_fall_run_lands_only_on_a_body_stretched_on_the_floor() {
        // A run stopping short, then lying read surely on points 0.4 m long (the legs of a
        // person standing): no fall. The same on a body 1.4 m long is one.
        let landing_on = |length: f64| {
            [
                (Walking, 5.0, true, Some(0.5), SURE),
                (FallingDown, 0.6, true, Some(0.5), SURE),
                (LyingDown, 2.0, true, Some(length), SURE),
            ]
        };
        let legs = run_scans(&mut without_descent(), &landing_on(0.4));
        assert!(legs.is_empty(), "{legs:?}");
        let body = run_scans(&mut without_descent(), &landing_on(1.4));
        assert_eq!(kinds(&body), [AlertKind::FallDetected]);
        // With the check off, the legs land it too.
        let mut unchecked = detector_with(|c| {
            c.descent_max_s = 0.0;
            c.landing_min_length_m = 0.0;
        });
        let legs = run_scans(&mut unchecked, &landing_on(0.4));
        assert_eq!(kinds(&legs), [AlertKind::FallDetected]);
    }

    #[test]
    fn upright_for_a_while_after_a_fall_run_drops_it() {
        // Read as falling, then standing, then lying within `fall_then_floor_s` of the run: a
        // moment standing is the model's misreading of a fallen person; walking on for a
        // second (past `fall_cancel_upright_s`, 0.75 s) is a person who staggered, then lay
        // down or was misread as lying. Upright time counts from the run's last scan, not
        // from when it counted, 0.2 s into the fall.
        let alerts = alerts_after_a_fall_run(&[(Standing, 0.3, true), (LyingDown, 3.0, true)]);
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
        assert!((alerts[0].event_time_s - 5.0).abs() < 1e-6, "{alerts:?}");
        let walked_on = [(WalkingUnsteadily, 1.0, true), (LyingDown, 3.0, true)];
        let alerts = alerts_after_a_fall_run(&walked_on);
        assert!(alerts.is_empty(), "{alerts:?}");
        // Waiting as long as the re-arm (1.5 s, before session 35), the run lands.
        let mut patient = detector_with(|c| {
            c.descent_max_s = 0.0;
            c.fall_cancel_upright_s = 1.5;
        });
        let alerts = run_after_a_fall_run(&mut patient, &walked_on);
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
    }

    #[test]
    fn lying_again_soon_after_getting_up_is_a_fall() {
        // Down, getting up (confirmed), then straight back to lying: a failed attempt to
        // stand. The getting up, though, starts no `falling_down` run (the model's commonest
        // false fall is getting up read as falling).
        let mut d = detector();
        let alerts = run(
            &mut d,
            &[
                (Walking, 5.0, true),
                (SittingOnFloor, 5.0, true),
                (GettingUp, 1.0, true),
                (LyingDown, 5.0, true),
            ],
        );
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
        let alerts = run(
            &mut detector(),
            &[
                (Walking, 5.0, true),
                (SittingOnFloor, 5.0, true),
                (GettingUp, 1.0, true),
                (FallingDown, 0.5, true),
                (SittingOnFloor, 5.0, true),
            ],
        );
        assert!(alerts.is_empty(), "{alerts:?}");
    }

    #[test]
    fn a_moment_read_as_getting_up_starts_no_descent() {
        // Crawling, read as getting up for `getting_up_s` (confirmed after 0.25 s), then as
        // lying: a crawler misread for a moment is no fall; a person who struggled up for a
        // while and dropped back is.
        let alerts_after_getting_up = |detector: &mut FallDetector, getting_up_s| {
            run(
                detector,
                &[
                    (Walking, 5.0, true),
                    (Crawling, 5.0, true),
                    (GettingUp, getting_up_s, true),
                    (LyingDown, 5.0, true),
                ],
            )
        };
        let alerts = alerts_after_getting_up(&mut detector(), 0.45);
        assert!(alerts.is_empty(), "{alerts:?}");
        let alerts = alerts_after_getting_up(&mut detector(), 0.6);
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
        // With the requirement off, the moment starts a descent too.
        let mut unchecked = detector_with(|c| c.descent_getting_up_s = 0.0);
        let alerts = alerts_after_getting_up(&mut unchecked, 0.45);
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
    }

    #[test]
    fn a_descent_needs_a_body_stretched_on_the_floor() {
        // Standing, then half a second the classifier reads as lying, on the same two legs.
        let script = |lying_length: f64| {
            [
                (Standing, 5.0, 0.4),
                (LyingDown, 0.5, lying_length),
                (Standing, 5.0, 0.4),
            ]
        };
        let legs = run_with_lengths(&mut detector(), &script(0.4));
        assert!(legs.is_empty(), "{legs:?}");
        // A body stretched on the floor is a descent.
        let body = run_with_lengths(&mut detector(), &script(1.4));
        assert_eq!(kinds(&body), [AlertKind::FallDetected]);
        // ... and so are the two legs with the check off.
        let mut unchecked = detector_with(|c| c.descent_min_length_m = 0.0);
        let unchecked = run_with_lengths(&mut unchecked, &script(0.4));
        assert_eq!(kinds(&unchecked), [AlertKind::FallDetected]);
    }

    #[test]
    fn a_descent_needs_the_classifier_to_be_sure_of_lying() {
        // Walking, then lying on the floor for good, read as lying with probability p.
        let script = |p: f32| {
            [
                (Walking, 5.0, true, Some(0.5), SURE),
                (LyingDown, 3.0, true, Some(1.4), p),
            ]
        };
        // A crawler the classifier takes for lying hesitantly is not a fall ...
        let hesitant = run_scans(&mut detector(), &script(0.6));
        assert!(hesitant.is_empty(), "{hesitant:?}");
        // ... a body it reads as lying at once is.
        let sure = run_scans(&mut detector(), &script(SURE));
        assert_eq!(kinds(&sure), [AlertKind::FallDetected]);
        // With the check off the hesitant reading is a descent too.
        let mut unchecked = detector_with(|c| c.descent_min_probability = 0.0);
        let unchecked = run_scans(&mut unchecked, &script(0.6));
        assert_eq!(kinds(&unchecked), [AlertKind::FallDetected]);
    }

    #[test]
    fn one_long_view_does_not_make_a_crawler_a_fallen_body() {
        // The length rule alone: the classifier's doubt about lying is not checked here.
        let detector = || detector_with(|c| c.descent_min_probability = 0.0);
        // A crawler seen end-on, read as getting up for 0.6 s (long enough to start a
        // descent), then lying on the scan that confirms the floor again: that one scan's
        // points happen to stretch 0.95 m.
        let script = |spike: f64| {
            [
                (Crawling, 3.0, 0.5),
                (GettingUp, 0.6, 0.45),
                (Crawling, 0.2, 0.5),
                (LyingDown, DT, spike),
                (Crawling, 2.0, 0.5),
            ]
        };
        let crawler = run_with_lengths(&mut detector(), &script(0.95));
        assert!(crawler.is_empty(), "{crawler:?}");
        // The same posture changes on a body stretched out on every scan are a descent.
        let body = run_with_lengths(
            &mut detector(),
            &[
                (Crawling, 3.0, 1.2),
                (GettingUp, 0.6, 0.45),
                (Crawling, 0.2, 1.2),
                (LyingDown, DT, 1.2),
                (Crawling, 2.0, 1.2),
            ],
        );
        assert_eq!(kinds(&body), [AlertKind::FallDetected]);
    }

    #[test]
    fn a_moment_read_upright_while_down_does_not_restart_the_clock() {
        // Fallen, then sitting on the floor, misread as walking for `walking_s` in between.
        let script = |walking_s: f64| {
            [
                (Walking, 5.0, true),
                (FallingDown, 1.0, true),
                (LyingDown, 3.0, true),
                (SittingOnFloor, 3.0, true),
                (Walking, walking_s, true),
                (SittingOnFloor, 12.0, true),
            ]
        };
        let detector = || detector_with(|c| c.down_ends_upright_s = 1.0);
        // 0.4 s upright: still down since the fall, alerted 15 s after it.
        let alerts = run(&mut detector(), &script(0.4));
        assert_eq!(
            kinds(&alerts),
            [AlertKind::FallDetected, AlertKind::PersonDown]
        );
        assert!((alerts[1].down_since_s - 5.0).abs() < 1e-9, "{alerts:?}");
        assert!((alerts[1].event_time_s - 20.0).abs() < 1e-9, "{alerts:?}");
        // 1.2 s upright: up again; sitting down afterwards starts a new clock (not yet 15 s).
        let alerts = run(&mut detector(), &script(1.2));
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
        // With 0, the 0.4 s already ends the spell.
        let mut at_once = detector_with(|c| c.down_ends_upright_s = 0.0);
        let alerts = run(&mut at_once, &script(0.4));
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
    }

    #[test]
    fn being_read_up_with_doubt_while_down_does_not_restart_the_clock() {
        // Fallen, then sitting on the floor, read as `up` for `up_s` at probability `p`
        // (p_unsure for its first half, p_sure for the rest) in between.
        let script = |up: Activity, up_s: f64, p_unsure: f32, p_sure: f32| {
            [
                (Walking, 5.0, true, None, SURE),
                (FallingDown, 1.0, true, None, SURE),
                (LyingDown, 3.0, true, None, SURE),
                (SittingOnFloor, 3.0, true, None, SURE),
                (up, up_s / 2.0, true, None, p_unsure),
                (up, up_s / 2.0, true, None, p_sure),
                (SittingOnFloor, 12.0 - up_s, true, None, SURE),
            ]
        };
        let still_down = [AlertKind::FallDetected, AlertKind::PersonDown];
        for up in [Standing, GettingUp] {
            // Read so at 0.6 for 2 s: still down since the fall, alerted 15 s after it.
            let alerts = run_scans(&mut detector(), &script(up, 2.0, 0.6, 0.6));
            assert_eq!(kinds(&alerts), still_down, "{up:?}");
            assert!((alerts[1].down_since_s - 5.0).abs() < 1e-9, "{alerts:?}");
            assert!((alerts[1].event_time_s - 20.0).abs() < 1e-9, "{alerts:?}");
            // Surely on half of those scans, or at 0.6 with the check off: up again.
            let alerts = run_scans(&mut detector(), &script(up, 2.0, 0.6, SURE));
            assert_eq!(kinds(&alerts), [AlertKind::FallDetected], "{up:?}");
            let mut off = detector_with(|c| c.down_ends_min_probability = 0.0);
            let alerts = run_scans(&mut off, &script(up, 2.0, 0.6, 0.6));
            assert_eq!(kinds(&alerts), [AlertKind::FallDetected], "{up:?}");
        }
    }

    #[test]
    fn without_a_fall_being_read_up_with_doubt_still_ends_the_spell() {
        // Sat down on the floor (no fall), misread as standing at 0.6 for 2 s, sat on.
        let script = [
            (Walking, 5.0, true, None, SURE),
            (SittingOnFloor, 8.0, true, None, SURE),
            (Standing, 2.0, true, None, 0.6),
            (SittingOnFloor, 10.0, true, None, SURE),
        ];
        let alerts = run_scans(&mut detector(), &script);
        assert!(alerts.is_empty(), "{alerts:?}");
    }

    #[test]
    fn after_a_fall_getting_up_ends_the_spell_only_once_read_so_a_while() {
        // Fallen, then read surely as getting up for `getting_up_s` (sitting up), then
        // sitting on the floor.
        let script = |getting_up_s: f64| {
            [
                (Walking, 5.0, true),
                (FallingDown, 1.0, true),
                (LyingDown, 3.0, true),
                (GettingUp, getting_up_s, true),
                (SittingOnFloor, 12.0, true),
            ]
        };
        let alerts = run(&mut detector(), &script(0.3));
        assert_eq!(
            kinds(&alerts),
            [AlertKind::FallDetected, AlertKind::PersonDown]
        );
        assert!((alerts[1].down_since_s - 5.0).abs() < 1e-9, "{alerts:?}");
        let alerts = run(&mut detector(), &script(0.8));
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
        let mut at_once = detector_with(|c| c.down_ends_getting_up_s = 0.0);
        let alerts = run(&mut at_once, &script(0.3));
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
    }

    #[test]
    fn being_read_up_with_doubt_after_person_down_does_not_raise_it_again() {
        // Alerted as down, then misread as standing at 0.6 for longer than rearm_upright_s,
        // then read on the floor again: still the same spell, and no new fall (lying again
        // after the doubtful standing had passed for a descent until session 59).
        let script = |standing_p: f32, then: Activity| {
            [
                (Walking, 5.0, true, None, SURE),
                (FallingDown, 1.0, true, None, SURE),
                (LyingDown, 16.0, true, None, SURE),
                (Standing, 2.0, true, None, standing_p),
                (then, 20.0, true, None, SURE),
            ]
        };
        for then in [SittingOnFloor, LyingDown] {
            let alerts = run_scans(&mut detector(), &script(0.6, then));
            assert_eq!(
                kinds(&alerts),
                [AlertKind::FallDetected, AlertKind::PersonDown],
                "{then:?}"
            );
        }
        // Surely up for 2 s, then lying at once: a new fall.
        let alerts = run_scans(&mut detector(), &script(SURE, LyingDown));
        assert_eq!(
            kinds(&alerts),
            [
                AlertKind::FallDetected,
                AlertKind::PersonDown,
                AlertKind::FallDetected,
                AlertKind::PersonDown
            ]
        );
    }

    #[test]
    fn a_fall_vouches_for_the_floor_while_its_spell_lasts() {
        // Fallen, then read as getting up with doubt for long enough to re-arm
        // FALL_DETECTED (not to end the spell), then as lying on points as short as legs.
        let script = |getting_up_p: f32| {
            [
                (Walking, 5.0, true, Some(0.3), SURE),
                (FallingDown, 1.0, true, Some(0.5), SURE),
                (LyingDown, 3.0, true, Some(1.2), SURE),
                (GettingUp, 1.2, true, Some(0.5), getting_up_p),
                (LyingDown, 20.0, true, Some(0.3), SURE),
            ]
        };
        let alerts = run_scans(&mut detector(), &script(0.6));
        assert_eq!(
            kinds(&alerts),
            [AlertKind::FallDetected, AlertKind::PersonDown]
        );
        assert!((alerts[1].down_since_s - 5.0).abs() < 1e-9, "{alerts:?}");
        // Surely up in between: a new spell, and short points on the floor prove nothing.
        let alerts = run_scans(&mut detector(), &script(SURE));
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
    }

    #[test]
    fn one_fall_then_staying_down_gives_one_fall_and_one_person_down() {
        let mut d = detector();
        let alerts = run(
            &mut d,
            &[
                (Walking, 5.0, true),
                (FallingDown, 1.0, true),
                (LyingDown, 40.0, true),
            ],
        );
        assert_eq!(
            kinds(&alerts),
            [AlertKind::FallDetected, AlertKind::PersonDown]
        );
        let fall = alerts[0];
        assert!((fall.event_time_s - 5.0).abs() < 1e-9, "{fall:?}");
        // Raised once lying is confirmed (confirm_scans): 0.2 s after the landing at 6 s.
        assert!((fall.raised_at_s - 6.2).abs() < 1e-6, "{fall:?}");
        assert_eq!(fall.position, DVec2::new(1.0, 2.0));
        assert!((fall.confidence - SURE).abs() < 1e-6);
        let down = alerts[1];
        assert!((down.down_since_s - 5.0).abs() < 1e-9);
        assert!((down.event_time_s - 20.0).abs() < 1e-9);
        assert!(down.raised_at_s - down.event_time_s <= DT + 1e-9);
        assert!(down.confidence > 0.85 && down.confidence <= 1.0, "{down:?}");
    }

    #[test]
    fn fall_then_getting_up_gives_only_the_fall_alert() {
        let mut d = detector();
        let alerts = run(
            &mut d,
            &[
                (Walking, 3.0, true),
                (FallingDown, 1.0, true),
                (LyingDown, 5.0, true),
                (GettingUp, 2.0, true),
                (Walking, 30.0, true),
            ],
        );
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected]);
    }

    #[test]
    fn flicker_does_not_retrigger() {
        let mut d = detector();
        // Fall, then lying with falling_down flickering back in, then a brief upright
        // misclassification shorter than rearm_upright_s.
        let alerts = run(
            &mut d,
            &[
                (Walking, 3.0, true),
                (FallingDown, 1.0, true),
                (LyingDown, 2.0, true),
                (FallingDown, 0.5, true),
                (LyingDown, 2.0, true),
                (Standing, 0.5, true),
                (LyingDown, 1.0, true),
                (FallingDown, 0.5, true),
                (LyingDown, 30.0, true),
            ],
        );
        assert_eq!(
            kinds(&alerts),
            [AlertKind::FallDetected, AlertKind::PersonDown]
        );
    }

    #[test]
    fn single_scans_of_falling_do_not_alert() {
        let mut d = detector();
        let mut script = vec![];
        for _ in 0..50 {
            script.push((Walking, 0.5, true));
            script.push((FallingDown, 0.1, true)); // two scans < fall_min_scans
        }
        assert!(run(&mut d, &script).is_empty());
    }

    /// The alert kinds raised by a seen fall, lying, getting up, then `after`.
    fn kinds_after_a_fall_and_getting_up(after: &[(Activity, f64, bool)]) -> Vec<AlertKind> {
        let fall_and_getting_up = [
            (Walking, 3.0, true),
            (FallingDown, 1.0, true),
            (LyingDown, 3.0, true),
            (GettingUp, 2.0, true),
        ];
        kinds(&run(
            &mut detector(),
            &[&fall_and_getting_up, after].concat(),
        ))
    }

    #[test]
    fn second_fall_after_recovery_alerts_again() {
        let kinds = kinds_after_a_fall_and_getting_up(&[
            (Walking, 10.0, true),
            (FallingDown, 1.0, true),
            (LyingDown, 3.0, true),
        ]);
        assert_eq!(kinds, [AlertKind::FallDetected, AlertKind::FallDetected]);
    }

    #[test]
    fn falling_back_after_struggling_up_for_a_while_is_a_new_fall() {
        // Never upright between the two falls: up for 2 s, then down again.
        let fall_back = [(FallingDown, 1.0, true), (LyingDown, 3.0, true)];
        assert_eq!(
            kinds_after_a_fall_and_getting_up(&fall_back),
            [AlertKind::FallDetected, AlertKind::FallDetected]
        );
        let fell = [
            (Walking, 3.0, true),
            (FallingDown, 1.0, true),
            (LyingDown, 3.0, true),
        ];
        let after_a_fall = |mut detector: FallDetector, then: &[(Activity, f64, bool)]| {
            kinds(&run(&mut detector, &[&fell[..], then].concat()))
        };
        let without = detector_with(|c| {
            c.rearm_getting_up_s = 0.0;
            c.fall_from_getting_up = false;
        });
        let up_and_back = [(GettingUp, 2.0, true), fall_back[0], fall_back[1]];
        assert_eq!(
            after_a_fall(without, &up_and_back),
            [AlertKind::FallDetected]
        );
        // A moment read as getting up while lying re-arms nothing; nor do two stretches of
        // it broken by another reading (a person lying seen in glimpses is read so now and
        // then): the descent into lying again stays silent.
        let brief = [(GettingUp, 0.5, true), (LyingDown, 3.0, true)];
        assert_eq!(after_a_fall(detector(), &brief), [AlertKind::FallDetected]);
        let broken = [
            (GettingUp, 0.7, true),
            (SittingOnFloor, 0.05, true),
            (GettingUp, 0.7, true),
            (LyingDown, 3.0, true),
        ];
        assert_eq!(after_a_fall(detector(), &broken), [AlertKind::FallDetected]);
    }

    #[test]
    fn a_landing_alerted_as_a_descent_is_not_alerted_again_by_a_run_waiting_for_it() {
        // A fall; then a struggle: read as falling on a few scans (a run from getting up,
        // counted while the alert is disarmed, waiting for its landing), up again long enough
        // to re-arm, and down for good. The descent alerts that landing; the run that waited
        // for it is the same incident, not a fall of its own a scan later.
        let body = Some(1.2);
        let script = [
            (Standing, 3.0, true, body, SURE),
            (FallingDown, 0.5, true, body, 0.9),
            (LyingDown, 3.0, true, body, SURE),
            (GettingUp, 0.8, true, body, SURE),
            (FallingDown, 0.25, true, body, 0.9),
            (GettingUp, 1.15, true, body, SURE),
            (SittingOnFloor, 0.1, true, body, SURE),
            (LyingDown, 3.0, true, body, SURE),
        ];
        let alerts = run_scans(&mut detector(), &script);
        assert_eq!(
            kinds(&alerts),
            [AlertKind::FallDetected, AlertKind::FallDetected],
            "{alerts:?}"
        );
    }

    #[test]
    fn falling_back_after_half_a_second_of_getting_up_is_a_new_fall() {
        // Read as getting up for 0.6 s, as falling for a moment, getting up again, then as
        // falling and lying: never the unbroken second of getting up that re-arms.
        let fell = [
            (Walking, 3.0, true, None, SURE),
            (FallingDown, 1.0, true, None, SURE),
            (LyingDown, 3.0, true, None, SURE),
        ];
        let struggle_read = |getting_up_s: f64, falling_p: f32, lying_p: f32| {
            [
                (GettingUp, getting_up_s, true, None, SURE),
                (FallingDown, 0.1, true, None, SURE),
                (GettingUp, 0.3, true, None, SURE),
                (FallingDown, 0.8, true, None, falling_p),
                (LyingDown, 3.0, true, None, lying_p),
            ]
        };
        let struggle = |getting_up_s: f64, lying_p: f32| struggle_read(getting_up_s, 0.75, lying_p);
        let alerts = |mut detector: FallDetector,
                      then: &[(Activity, f64, bool, Option<f64>, f32)]| {
            kinds(&run_scans(&mut detector, &[&fell[..], then].concat()))
        };
        let twice = [AlertKind::FallDetected, AlertKind::FallDetected];
        assert_eq!(alerts(detector(), &struggle(0.6, SURE)), twice);
        let without = detector_with(|c| c.fall_from_getting_up = false);
        assert_eq!(
            alerts(without, &struggle(0.6, SURE)),
            [AlertKind::FallDetected]
        );
        // Getting up read for less than `descent_getting_up_s` each time: no new fall.
        assert_eq!(
            alerts(detector(), &struggle(0.3, SURE)),
            [AlertKind::FallDetected]
        );
        // The landing must be as sure of lying as a descent's (0.9), not a run's from
        // upright (0.8): a crawler read as getting up and then as falling lands with doubt.
        assert_eq!(
            alerts(detector(), &struggle(0.6, 0.85)),
            [AlertKind::FallDetected]
        );
        // ... unless the run was read surely falling (`sure_fall_run_probability`).
        assert_eq!(alerts(detector(), &struggle_read(0.6, SURE, 0.85)), twice);
        let never_sure = detector_with(|c| c.sure_fall_run_probability = 0.0);
        assert_eq!(
            alerts(never_sure, &struggle_read(0.6, SURE, 0.85)),
            [AlertKind::FallDetected]
        );
    }

    #[test]
    fn a_fall_back_down_read_as_falling_only_in_pieces_is_a_new_fall() {
        const BODY: Option<f64> = Some(1.4);
        let fell = [
            (Walking, 3.0, true, BODY, SURE),
            (FallingDown, 1.0, true, BODY, SURE),
            (LyingDown, 3.0, true, BODY, SURE),
        ];
        // Read as getting up, then as falling on 2 scans, getting up on 4 and falling on 3:
        // never `fall_min_scans` in a row, nor the unbroken second that re-arms.
        let struggle = |getting_up_s: f64, lying_p: f32| {
            [
                (GettingUp, getting_up_s, true, BODY, SURE),
                (FallingDown, 0.1, true, BODY, 0.5),
                (GettingUp, 0.2, true, BODY, SURE),
                (FallingDown, 0.15, true, BODY, 0.5),
                (LyingDown, 3.0, true, BODY, lying_p),
            ]
        };
        let alerts = |mut detector: FallDetector,
                      then: &[(Activity, f64, bool, Option<f64>, f32)]| {
            run_scans(&mut detector, &[&fell[..], then].concat())
        };
        let again = alerts(detector(), &struggle(0.6, SURE));
        assert_eq!(
            kinds(&again),
            [AlertKind::FallDetected, AlertKind::FallDetected]
        );
        // Dated from the first piece: 3 s walking, 1 s falling, 3 s lying, 0.6 s getting up.
        assert!((again[1].event_time_s - 7.6).abs() < 1e-9);
        for off in [
            detector_with(|c| c.broken_fall_run_scans = 0),
            detector_with(|c| c.fall_from_getting_up = false),
        ] {
            assert_eq!(
                kinds(&alerts(off, &struggle(0.6, SURE))),
                [AlertKind::FallDetected]
            );
        }
        // Getting up read for less than `descent_getting_up_s`, or a landing read as lying
        // with doubt (0.85, below a descent's 0.9): no new fall.
        for (getting_up_s, lying_p) in [(0.3, SURE), (0.6, 0.85)] {
            assert_eq!(
                kinds(&alerts(detector(), &struggle(getting_up_s, lying_p))),
                [AlertKind::FallDetected]
            );
        }
    }

    #[test]
    fn a_fall_read_as_falling_only_in_pieces_lands_like_a_fall_run() {
        const BODY: Option<f64> = Some(1.4);
        // Read as falling on 2 scans, sitting on 4, falling on 3: never fall_min_scans in a
        // row. Then lying at `lying_p` for `doubt_s`, and surely after.
        let fall_in_pieces = |lying_p: f32, doubt_s: f64| {
            [
                (FallingDown, 0.1, true, BODY, 0.5),
                (SittingOnFloor, 0.2, true, BODY, 0.5),
                (FallingDown, 0.15, true, BODY, 0.5),
                (LyingDown, doubt_s, true, BODY, lying_p),
                (LyingDown, 3.0, true, BODY, SURE),
            ]
        };
        let alerts = |mut detector: FallDetector,
                      before: &[(Activity, f64, bool, Option<f64>, f32)],
                      fall: &[(Activity, f64, bool, Option<f64>, f32)]| {
            run_scans(&mut detector, &[before, fall].concat())
        };
        let walked = [(Walking, 3.0, true, BODY, SURE)];
        // Lying at 0.85: a landing (0.8), not a descent (0.9). Dated from the first piece.
        let fell = alerts(detector(), &walked, &fall_in_pieces(0.85, 0.25));
        assert_eq!(kinds(&fell), [AlertKind::FallDetected]);
        assert!((fell[0].event_time_s - 3.0).abs() < 1e-9);
        let off = detector_with(|c| c.broken_fall_run_scans = 0);
        assert!(alerts(off, &walked, &fall_in_pieces(0.85, 0.25)).is_empty());
        // Lying at 0.7 at first: no landing, and only the first scans of the lying count,
        // so none when it is read surely a moment later either.
        assert!(alerts(detector(), &walked, &fall_in_pieces(0.7, 0.25)).is_empty());
        // Upright only 1 s after crawling (`broken_fall_run_upright_s`): no fall.
        let crawled_then_walked = [
            (Crawling, 3.0, true, BODY, SURE),
            (Walking, 1.0, true, BODY, SURE),
        ];
        let crawler = alerts(
            detector(),
            &crawled_then_walked,
            &fall_in_pieces(0.85, 0.25),
        );
        assert!(!kinds(&crawler).contains(&AlertKind::FallDetected));
        let sooner = detector_with(|c| c.broken_fall_run_upright_s = 0.5);
        let crawler = alerts(sooner, &crawled_then_walked, &fall_in_pieces(0.85, 0.25));
        assert!(kinds(&crawler).contains(&AlertKind::FallDetected));
    }

    #[test]
    fn a_standing_person_misread_as_falling_for_a_moment_still_rearms() {
        // After the first fall: up and walking 3.8 s, with 0.3 s in the middle read as
        // falling (a confirmed falling posture, too short for a fall), then a real fall.
        let kinds = kinds_after_a_fall_and_getting_up(&[
            (Walking, 1.5, true),
            (FallingDown, 0.3, true),
            (Walking, 2.0, true),
            (FallingDown, 1.0, true),
            (LyingDown, 3.0, true),
        ]);
        assert_eq!(kinds, [AlertKind::FallDetected, AlertKind::FallDetected]);
    }

    #[test]
    fn hidden_fall_still_gives_person_down() {
        let mut d = detector();
        // Seen walking, hidden for the fall, found lying later.
        let alerts = run(
            &mut d,
            &[
                (Walking, 5.0, true),
                (FallingDown, 1.0, false),
                (Walking, 5.0, false),
                (LyingDown, 20.0, true),
            ],
        );
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
        // The clock starts when the person is first confirmed down (at 11 s).
        assert!(
            (alerts[0].down_since_s - 11.0).abs() < 1e-9,
            "{:?}",
            alerts[0]
        );
    }

    /// A walker read on the floor for a few scans as they leave view, out of sight for a
    /// minute, then seen `then` for `for_s`: the readings before the minute are no part of
    /// what the robot sees afterwards.
    fn stray_scans_then_a_minute_away(
        stray: Activity,
        stray_scans: u32,
        then: Activity,
        for_s: f64,
    ) -> Vec<FallAlert> {
        run(
            &mut detector(),
            &[
                (Walking, 3.0, true),
                (stray, f64::from(stray_scans) * DT, true),
                (Walking, 60.0, false),
                (then, for_s, true),
            ],
        )
    }

    #[test]
    fn floor_readings_before_a_minute_out_of_sight_do_not_date_the_floor_posture() {
        // Found sitting on the floor for 5 s (due after 15 s): no alert, however many of the
        // scans as the person left view were read as sitting (too few to confirm it).
        for stray_scans in 1..=4 {
            let alerts =
                stray_scans_then_a_minute_away(SittingOnFloor, stray_scans, SittingOnFloor, 5.0);
            assert!(alerts.is_empty(), "{stray_scans} stray scans: {alerts:?}");
        }
        // Found lying: down from when they were found (63.1 s), not a descent from being
        // upright a minute earlier (as `hidden_fall_still_gives_person_down`).
        let alerts = stray_scans_then_a_minute_away(LyingDown, 2, LyingDown, 20.0);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
        assert!(
            (alerts[0].down_since_s - 63.1).abs() < 1e-6,
            "{:?}",
            alerts[0]
        );
    }

    #[test]
    fn a_falling_run_does_not_span_a_minute_out_of_sight() {
        // 2 scans read as falling, a minute away, 3 more and lying for a second: no run of
        // 5, and no fall.
        let alerts = run(
            &mut detector(),
            &[
                (Walking, 3.0, true),
                (FallingDown, 0.1, true),
                (Walking, 60.0, false),
                (FallingDown, 0.15, true),
                (LyingDown, 1.0, true),
            ],
        );
        assert!(alerts.is_empty(), "{alerts:?}");
    }

    /// A fall alerted at 3.7 s (down since 3 s), then `after` (activity, seconds, seen);
    /// returns the alerts after the first.
    fn after_an_alerted_fall(after: &[(Activity, f64, bool)]) -> Vec<FallAlert> {
        let mut script = vec![
            (Walking, 3.0, true),
            (FallingDown, 0.5, true),
            (LyingDown, 3.0, true),
        ];
        script.extend_from_slice(after);
        let alerts = run(&mut detector(), &script);
        assert_eq!(alerts[0].kind, AlertKind::FallDetected, "{alerts:?}");
        alerts[1..].to_vec()
    }

    #[test]
    fn time_out_of_sight_does_not_count_as_seen_upright_or_getting_up() {
        // Misread as standing for 0.25 s, out of sight 2 s, lying again: one fall, still
        // down since it (seen upright 0.2 s, not the 1.5 s that re-arms).
        let alerts = after_an_alerted_fall(&[
            (Standing, 0.25, true),
            (LyingDown, 2.0, false),
            (LyingDown, 20.0, true),
        ]);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown], "{alerts:?}");
        // Nor as upright for `down_ends_upright_s`: the spell does not end.
        let alerts = after_an_alerted_fall(&[
            (Standing, 0.25, true),
            (LyingDown, 1.0, false),
            (Standing, 0.05, true),
            (LyingDown, 20.0, true),
        ]);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown], "{alerts:?}");
        assert!(
            (alerts[0].down_since_s - 3.0).abs() < 1e-6,
            "{:?}",
            alerts[0]
        );
        // Nor as getting up for `rearm_getting_up_s`: lying again is the same fall.
        let alerts = after_an_alerted_fall(&[
            (GettingUp, 0.25, true),
            (GettingUp, 1.0, false),
            (GettingUp, 0.05, true),
            (LyingDown, 5.0, true),
        ]);
        assert!(alerts.is_empty(), "{alerts:?}");
    }

    #[test]
    fn a_glimpse_gap_while_getting_up_still_counts() {
        // Getting up 0.8 s, out of sight 0.4 s (7 scans), getting up 0.3 s: read so on
        // every scan seen for over `rearm_getting_up_s`, then lying again: a second fall
        // (seed 2 episode 6 of `lidar-har alerts`).
        let alerts = after_an_alerted_fall(&[
            (GettingUp, 0.8, true),
            (GettingUp, 0.35, false),
            (GettingUp, 0.3, true),
            (LyingDown, 3.0, true),
        ]);
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected], "{alerts:?}");
    }

    #[test]
    fn a_shorter_glimpse_gap_breaks_the_getting_up_run() {
        // The script above with `glimpse_gap_s` under the 0.4 s out of sight: getting up is
        // read on 0.3 s seen since, not the second that re-arms, so lying again is the same
        // fall.
        let script = [
            (Walking, 3.0, true),
            (FallingDown, 0.5, true),
            (LyingDown, 3.0, true),
            (GettingUp, 0.8, true),
            (GettingUp, 0.35, false),
            (GettingUp, 0.3, true),
            (LyingDown, 3.0, true),
        ];
        let alerts = run(&mut detector_with(|c| c.glimpse_gap_s = 0.25), &script);
        assert_eq!(kinds(&alerts), [AlertKind::FallDetected], "{alerts:?}");
    }

    #[test]
    fn a_glimpse_gap_under_the_scan_period_breaks_no_run_of_scans_that_see_the_person() {
        // Seen on every scan: a fall and 20 s down raise both alerts, as with the default
        // (with 0 every run used to break between two scans, and nothing was alerted).
        let script = [
            (Walking, 3.0, true),
            (FallingDown, 0.5, true),
            (LyingDown, 20.0, true),
        ];
        let alerts = run(&mut detector_with(|c| c.glimpse_gap_s = 0.0), &script);
        assert_eq!(
            kinds(&alerts),
            [AlertKind::FallDetected, AlertKind::PersonDown],
            "{alerts:?}"
        );
    }

    /// Runs segments of (activity read, seconds, velocity in m/s) at 20 Hz, the person always
    /// seen, from the map origin; returns the alerts.
    fn run_moving(
        detector: &mut FallDetector,
        script: &[(Activity, f64, DVec2)],
    ) -> Vec<FallAlert> {
        let (mut t, mut position) = (0.0, DVec2::ZERO);
        let mut alerts = Vec::new();
        for &(activity, seconds, velocity) in script {
            for _ in 0..(seconds / DT).round() as usize {
                alerts.extend(detector.update(&FallInput {
                    stamp_s: t,
                    position: Some(position),
                    probabilities: one_hot(activity, SURE),
                    body_length_m: None,
                }));
                t += DT;
                position += velocity * DT;
            }
        }
        alerts
    }

    #[test]
    fn a_person_down_seen_covering_ground_like_a_walker_starts_the_clock_again() {
        // Sitting on the floor, then walking off while still read as sitting (as the model
        // misreads a walker it sees only in glimpses), then sitting down again.
        let walker = DVec2::new(1.2, 0.0);
        let script = [
            (SittingOnFloor, 6.0, DVec2::ZERO),
            (SittingOnFloor, 3.0, walker),
            (SittingOnFloor, 20.0, DVec2::ZERO),
        ];
        let travel =
            |m: f64| detector_with(|c| (c.down_travel_m, c.down_travel_within_s) = (m, 2.0));
        // Off: one spell from the start, alerted 15 s on.
        let alerts = run_moving(&mut travel(0.0), &script);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
        assert!(alerts[0].down_since_s < 0.1, "{alerts:?}");
        // 2 m within 2 s: covered 1.67 s into the walk, and the clock starts there.
        let alerts = run_moving(&mut travel(2.0), &script);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
        assert!((alerts[0].down_since_s - 7.67).abs() < 0.06, "{alerts:?}");
        // A crawler (0.3 m/s) never covers 2 m in 2 s: the clock runs on.
        let crawl = [
            (SittingOnFloor, 6.0, DVec2::ZERO),
            (Crawling, 10.0, DVec2::new(0.0, 0.3)),
            (SittingOnFloor, 5.0, DVec2::ZERO),
        ];
        let alerts = run_moving(&mut travel(2.0), &crawl);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
        assert!(alerts[0].down_since_s < 0.1, "{alerts:?}");
    }

    #[test]
    fn the_ground_a_fall_covers_does_not_start_the_clock_again() {
        // Walking at 1.2 m/s into a fall that carries the body on: only ground covered once
        // down counts, or the walk before the landing would restart the clock.
        let walker = DVec2::new(1.2, 0.0);
        let alerts = run_moving(
            &mut detector_with(|c| (c.down_travel_m, c.down_travel_within_s) = (2.0, 2.0)),
            &[
                (Walking, 5.0, walker),
                (FallingDown, 1.0, walker),
                (LyingDown, 20.0, DVec2::ZERO),
            ],
        );
        assert_eq!(
            kinds(&alerts),
            [AlertKind::FallDetected, AlertKind::PersonDown]
        );
        assert!((alerts[1].down_since_s - 5.0).abs() < 1e-9, "{alerts:?}");
    }

    #[test]
    fn hiding_while_down_does_not_reset_the_clock_but_counts_only_so_far() {
        let script = [
            (Standing, 3.0, true),
            (LyingDown, 5.0, true),
            (LyingDown, 12.0, false),
            (LyingDown, 10.0, true),
        ];
        // Every unseen second counted, as before `down_unseen_counts_s`: due at 18 s, but by
        // then the person was last seen on the floor 10 s before: found lying again at 20 s,
        // the alert comes at once, dated from when they went down.
        let mut d = detector_with(|c| {
            c.descent_max_s = 0.0;
            c.down_unseen_counts_s = 0.0;
        });
        let alerts = run(&mut d, &script);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
        assert!((alerts[0].event_time_s - 18.0).abs() < 1e-9);
        let raised = alerts[0].raised_at_s;
        assert!((20.0..20.5).contains(&raised), "{:?}", alerts[0]);

        // By default unseen from 7.95 s to 20 s, of which 1 s counts: 11.05 s do not, so 15 s
        // are counted at 29.05 s.
        let alerts = run(&mut without_descent(), &script);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
        let alert = alerts[0];
        assert!((alert.down_since_s - 3.0).abs() < 1e-9, "{alert:?}");
        assert!((alert.event_time_s - 29.05).abs() < 1e-6, "{alert:?}");
        assert!((alert.raised_at_s - 29.05).abs() < 1e-6, "{alert:?}");
    }

    #[test]
    fn stretches_out_of_sight_shorter_than_the_cap_count_in_full() {
        // Each view is `confirm_scans` long: enough to find the person down in it.
        let glimpses: Vec<_> = std::iter::once((Standing, 3.0, true))
            .chain(std::iter::once((LyingDown, 1.0, true)))
            .chain((0..20).flat_map(|_| [(LyingDown, 0.75, false), (LyingDown, 0.25, true)]))
            .collect();
        let alerts = run(&mut without_descent(), &glimpses);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
        assert!(alerts[0].raised_at_s < 18.3, "{:?}", alerts[0]);
    }

    #[test]
    fn a_person_who_gets_up_out_of_sight_is_not_alerted_as_down() {
        let script = [
            (Walking, 3.0, true),
            (SittingOnFloor, 6.0, true),
            (GettingUp, 2.0, false),
            (Walking, 30.0, false),
        ];
        let alerts = run(&mut detector(), &script);
        assert!(alerts.is_empty(), "{alerts:?}");
        // Either hold keeps it quiet alone: the fresh evidence, or counting little of the
        // time out of sight.
        let alerts = run(&mut detector_with(|c| c.down_seen_within_s = 0.0), &script);
        assert!(alerts.is_empty(), "{alerts:?}");
        let alerts = run(
            &mut detector_with(|c| c.down_unseen_counts_s = 0.0),
            &script,
        );
        assert!(alerts.is_empty(), "{alerts:?}");
        let mut neither = detector_with(|c| {
            c.down_seen_within_s = 0.0;
            c.down_unseen_counts_s = 0.0;
        });
        assert_eq!(kinds(&run(&mut neither, &script)), [AlertKind::PersonDown]);
    }

    #[test]
    fn an_upright_glimpse_holds_person_down_until_read_on_the_floor_again() {
        let script = [
            (Walking, 3.0, true),
            (SittingOnFloor, 14.8, true),
            (Walking, 0.1, true), // read upright for two scans, not confirmed
            (SittingOnFloor, 3.0, false),
            (SittingOnFloor, 1.0, true),
        ];
        // Every unseen second counted: due at 18 s, held through the hidden time, raised once
        // read sitting again at 20.9 s.
        let uncapped = |c: &mut FallAlertConfig| c.down_unseen_counts_s = 0.0;
        let alerts = run(&mut detector_with(uncapped), &script);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
        assert!((alerts[0].event_time_s - 18.0).abs() < 1e-9);
        assert!(alerts[0].raised_at_s > 20.85, "{:?}", alerts[0]);

        let mut d = detector_with(|c| {
            uncapped(c);
            c.down_waits_on_upright_glimpse = false;
        });
        let alerts = run(&mut d, &script);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
        assert!(alerts[0].raised_at_s < 18.1, "{:?}", alerts[0]);
    }

    #[test]
    fn a_standing_person_read_as_lying_is_not_alerted_as_down() {
        // Two legs (0.3 m) read as lying for 20 s: never found on the floor.
        let legs = [(Standing, 3.0, 0.3), (LyingDown, 20.0, 0.3)];
        let alerts = run_with_lengths(&mut without_descent(), &legs);
        assert!(alerts.is_empty(), "{alerts:?}");
        let mut unchecked = detector_with(|c| {
            c.descent_max_s = 0.0;
            c.down_lying_min_length_m = 0.0;
        });
        assert_eq!(
            kinds(&run_with_lengths(&mut unchecked, &legs)),
            [AlertKind::PersonDown]
        );
        // Nor when a few scans in a row stretch as far as a body (the median is over 20).
        let now_and_then_long: Vec<_> = std::iter::once((Standing, 3.0, 0.3))
            .chain((0..400).map(|i| (LyingDown, DT, if i % 20 < 4 { 0.7 } else { 0.3 })))
            .collect();
        let alerts = run_with_lengths(&mut without_descent(), &now_and_then_long);
        assert!(alerts.is_empty(), "{alerts:?}");
        let mut over_the_run = detector_with(|c| {
            c.descent_max_s = 0.0;
            c.down_lying_length_scans = c.confirm_scans;
        });
        let alerts = run_with_lengths(&mut over_the_run, &now_and_then_long);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
        // A fall alerted first vouches for the floor: short as a standing person (sitting),
        // still down.
        let fell = [
            (Standing, 3.0, 0.3),
            (LyingDown, 1.0, 1.2),
            (LyingDown, 19.0, 0.25),
        ];
        let alerts = run_with_lengths(&mut detector(), &fell);
        assert_eq!(
            kinds(&alerts),
            [AlertKind::FallDetected, AlertKind::PersonDown]
        );

        // A body stretched on the floor is: due at 18 s.
        let body = [(Standing, 3.0, 0.3), (LyingDown, 20.0, 1.2)];
        let alerts = run_with_lengths(&mut without_descent(), &body);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
        assert!(
            (alerts[0].event_time_s - 18.0).abs() < 1e-9,
            "{:?}",
            alerts[0]
        );

        // So is one seen in part, its points 0.3 to 0.9 m scan by scan: the median decides.
        let in_part: Vec<_> = std::iter::once((Standing, 3.0, 0.3))
            .chain((0..400).map(|i| (LyingDown, DT, [0.3, 0.6, 0.9, 0.45][i % 4])))
            .collect();
        let alerts = run_with_lengths(&mut without_descent(), &in_part);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
    }

    #[test]
    fn glimpses_read_as_sitting_do_not_find_a_person_down() {
        // Walking, then 20 s seen only in glimpses of 3 scans between 2 hidden ones, each
        // read as sitting on the floor (a walker far down a hall), then `in_view_s` in view.
        let glimpses_then_in_view = |in_view_s| {
            let mut script = vec![(Walking, 5.0, true)];
            for _ in 0..80 {
                script.extend([(SittingOnFloor, 0.15, true), (SittingOnFloor, 0.1, false)]);
            }
            script.push((SittingOnFloor, in_view_s, true));
            script
        };
        let alerts = run(&mut detector(), &glimpses_then_in_view(0.0));
        assert!(alerts.is_empty(), "{alerts:?}");
        // In view for 5 scans in a row, the person is found down: the alert is due.
        let alerts = run(&mut detector(), &glimpses_then_in_view(0.25));
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
        // Letting the glimpses add up finds them down without it.
        let mut glimpses_add_up = detector_with(|c| c.down_found_in_view = false);
        let alerts = run(&mut glimpses_add_up, &glimpses_then_in_view(0.0));
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
    }

    #[test]
    fn a_person_crawling_about_is_alerted_as_down_only_once_seen_lying_or_sitting() {
        let crawling_on = [
            (Walking, 3.0, true),
            (SittingOnFloor, 5.0, true),
            (Crawling, 12.0, true),
        ];
        // Down since 3 s, due at 18 s, but last seen sitting at 8 s: crawling is not evidence.
        let alerts = run(&mut detector(), &crawling_on);
        assert!(alerts.is_empty(), "{alerts:?}");

        let mut d = detector_with(|c| c.crawling_shows_down = true);
        let alerts = run(&mut d, &crawling_on);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);

        // Sitting again after the crawl: due since 18 s, raised once sitting is confirmed.
        let mut then_sitting = crawling_on.to_vec();
        then_sitting.push((SittingOnFloor, 1.0, true));
        let alerts = run(&mut detector(), &then_sitting);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
        assert!((alerts[0].event_time_s - 18.0).abs() < 1e-9);
        assert!(
            (20.15..20.3).contains(&alerts[0].raised_at_s),
            "{:?}",
            alerts[0]
        );
    }

    #[test]
    fn glimpses_of_getting_up_hold_person_down_even_when_the_last_reads_the_floor() {
        // Getting up in glimpses, the last of them read as crawling, then out of sight.
        let script = [
            (Walking, 3.0, true),
            (SittingOnFloor, 14.0, true),
            (GettingUp, 0.1, true),
            (Crawling, 0.1, true),
            (Walking, 10.0, false),
        ];
        let alerts = run(&mut detector(), &script);
        assert!(alerts.is_empty(), "{alerts:?}");
        let mut d = detector_with(|c| c.down_waits_on_upright_glimpse = false);
        assert_eq!(kinds(&run(&mut d, &script)), [AlertKind::PersonDown]);
    }

    #[test]
    fn getting_up_and_sitting_down_again_restarts_the_clock() {
        let alerts = run(
            &mut without_descent(),
            &[
                (Walking, 3.0, true),
                (SittingOnFloor, 8.0, true),
                (GettingUp, 2.0, true), // all the way up, then straight down again
                (SittingOnFloor, 8.0, true),
            ],
        );
        assert!(alerts.is_empty(), "{alerts:?}");
    }

    /// Seed 4 episode 327 of `lidar-har alerts`: up for a moment too short to confirm, then
    /// read as falling on the way back down to sitting.
    #[test]
    fn read_as_falling_while_down_restarts_the_clock() {
        let script = [
            (Walking, 3.0, true),
            (SittingOnFloor, 10.0, true),
            (GettingUp, 0.2, true),
            (FallingDown, 1.2, true), // not from upright: no fall, but they were up
            (SittingOnFloor, 8.0, true),
        ];
        let alerts = run(&mut detector(), &script);
        assert!(alerts.is_empty(), "{alerts:?}");
        let mut off = detector_with(|c| c.down_restarts_on_fall_run = false);
        let alerts = run(&mut off, &script);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown], "{alerts:?}");
        // Counted from the first sitting, not from the fall run.
        assert!((alerts[0].raised_at_s - 18.0).abs() < 0.3, "{alerts:?}");
        // A run too short to count restarts nothing.
        let mut short = script;
        short[3].1 = 0.2;
        let alerts = run(&mut detector(), &short);
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown], "{alerts:?}");
    }

    /// The clock restarted by a falling run starts a new spell, and the travel rule then
    /// counts only ground covered since: where the person sat before the run is not
    /// measured against where the run carried them.
    #[test]
    fn a_falling_run_while_down_forgets_where_the_person_was_before_it() {
        let mover = DVec2::new(1.5, 0.0);
        let alerts = run_moving(
            &mut detector(),
            &[
                (SittingOnFloor, 10.0, DVec2::ZERO),
                (GettingUp, 0.2, mover),
                (FallingDown, 1.2, mover), // 2.1 m from the seat by its end, 1.3 s after
                (SittingOnFloor, 20.0, DVec2::ZERO),
            ],
        );
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown], "{alerts:?}");
        // From the run's start, not from where 2 m from the seat was reached (11.33 s).
        assert!((alerts[0].down_since_s - 10.2).abs() < 0.06, "{alerts:?}");
    }

    #[test]
    fn a_person_getting_up_slowly_is_not_alerted_as_down() {
        let alerts = run(
            &mut without_descent(),
            &[
                (Walking, 2.0, true),
                (LyingDown, 14.5, true),
                (GettingUp, 3.0, true), // due at 17 s, 0.5 s into getting up
                (Walking, 5.0, true),
            ],
        );
        assert!(alerts.is_empty(), "{alerts:?}");
    }

    #[test]
    fn sitting_briefly_gives_no_alert() {
        let mut d = detector();
        let alerts = run(
            &mut d,
            &[
                (Walking, 5.0, true),
                (SittingOnFloor, 10.0, true),
                (GettingUp, 2.0, true),
                (Standing, 5.0, true),
                (SittingOnFloor, 10.0, true),
                (Standing, 5.0, true),
            ],
        );
        assert!(alerts.is_empty(), "{alerts:?}");
    }

    #[test]
    fn sitting_too_long_gives_person_down_once() {
        let mut d = detector();
        let alerts = run(
            &mut d,
            &[(Walking, 2.0, true), (SittingOnFloor, 60.0, true)],
        );
        assert_eq!(kinds(&alerts), [AlertKind::PersonDown]);
    }

    #[test]
    fn person_down_rearms_only_after_standing_a_while() {
        let mut d = without_descent();
        let alerts = run(
            &mut d,
            &[
                (LyingDown, 20.0, true),
                (Standing, 1.0, true), // too short to re-arm
                (LyingDown, 20.0, true),
                (Standing, 5.0, true),
                (LyingDown, 20.0, true),
            ],
        );
        assert_eq!(
            kinds(&alerts),
            [AlertKind::PersonDown, AlertKind::PersonDown]
        );
    }

    #[test]
    fn low_confidence_falls_are_ignored() {
        let mut d = detector();
        let mut t = 0.0;
        for _ in 0..100 {
            let alerts = d.update(&FallInput {
                stamp_s: t,
                position: Some(DVec2::ZERO),
                probabilities: one_hot(FallingDown, 0.5),
                body_length_m: None,
            });
            assert!(alerts.is_empty());
            t += DT;
        }
    }

    #[test]
    fn non_finite_input_is_ignored_and_time_going_back_resets() {
        let mut d = detector();
        let nan = [f32::NAN; 9];
        assert!(
            d.update(&FallInput {
                stamp_s: 0.0,
                position: Some(DVec2::ZERO),
                probabilities: nan,
                body_length_m: None,
            })
            .is_empty()
        );
        assert!(
            d.update(&FallInput {
                stamp_s: f64::NAN,
                position: Some(DVec2::ZERO),
                probabilities: one_hot(LyingDown, 0.9),
                body_length_m: None,
            })
            .is_empty()
        );
        run(&mut d, &[(LyingDown, 10.0, true)]);
        assert!(d.down_since_s().is_some());
        // A replay restarting from 0: the state is cleared.
        d.update(&FallInput {
            stamp_s: 0.0,
            position: None,
            probabilities: one_hot(Walking, 0.9),
            body_length_m: None,
        });
        assert!(d.down_since_s().is_none());
    }

    #[test]
    fn bad_config_is_rejected_naming_the_field() {
        let config = FallAlertConfig {
            fall_probability: 1.5,
            ..Default::default()
        };
        let e = FallDetector::new(config).unwrap_err().to_string();
        assert!(e.contains("fall_probability"), "{e}");
        let config = FallAlertConfig {
            fall_from_upright_s: -1.0,
            ..Default::default()
        };
        let e = FallDetector::new(config).unwrap_err().to_string();
        assert!(e.contains("fall_from_upright_s"), "{e}");
        let config = FallAlertConfig {
            descent_min_length_m: f64::INFINITY,
            ..Default::default()
        };
        let e = FallDetector::new(config).unwrap_err().to_string();
        assert!(e.contains("descent_min_length_m"), "{e}");
        let config = FallAlertConfig {
            down_travel_m: -2.0,
            ..Default::default()
        };
        let e = FallDetector::new(config).unwrap_err().to_string();
        assert!(e.contains("down_travel_m"), "{e}");
        let config = FallAlertConfig {
            glimpse_gap_s: f64::NAN,
            ..Default::default()
        };
        let e = FallDetector::new(config).unwrap_err().to_string();
        assert!(e.contains("glimpse_gap_s"), "{e}");
        let config = FallAlertConfig {
            down_after_s: f64::NAN,
            ..Default::default()
        };
        assert!(FallDetector::new(config).is_err());
    }
}
