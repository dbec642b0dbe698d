//! Layout of the 12 upper-surface pressure taps: six per half-wing at three chordwise and two
//! spanwise stations (paper Fig. 1 gives the real layout as a drawing only; this is a stand-in
//! with the same count and symmetry).

/// Half-wing of a tap.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// Left half-wing.
    Port = 0,
    /// Right half-wing.
    Starboard = 1,
}

/// Position of one tap.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TapLayout {
    /// Half-wing.
    pub side: Side,
    /// Distance from the apex as a fraction of the root chord.
    pub chord_fraction: f64,
    /// Distance from the centreline as a fraction of the semi-span.
    pub span_fraction: f64,
}

const fn tap(side: Side, chord_fraction: f64, span_fraction: f64) -> TapLayout {
    TapLayout { side, chord_fraction, span_fraction }
}

/// `cp01`..`cp06` on the port half-wing, `cp07`..`cp12` mirrored on the starboard one.
pub const TAPS: [TapLayout; 12] = [
    tap(Side::Port, 0.35, 0.25),
    tap(Side::Port, 0.35, 0.55),
    tap(Side::Port, 0.55, 0.30),
    tap(Side::Port, 0.55, 0.65),
    tap(Side::Port, 0.75, 0.35),
    tap(Side::Port, 0.75, 0.75),
    tap(Side::Starboard, 0.35, 0.25),
    tap(Side::Starboard, 0.35, 0.55),
    tap(Side::Starboard, 0.55, 0.30),
    tap(Side::Starboard, 0.55, 0.65),
    tap(Side::Starboard, 0.75, 0.35),
    tap(Side::Starboard, 0.75, 0.75),
];
