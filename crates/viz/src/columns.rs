//! Frames of a run buffered in memory and sent to Rerun in columns.

use rerun::components::{RotationQuat, Translation3D};
use rerun::external::arrow::array::FixedSizeBinaryArray;
use rerun::external::arrow::buffer::Buffer;
use rerun::log::{Chunk, ChunkId, RowId};
use rerun::SerializedComponentColumn;
use std::time::{Duration, Instant};

use rerun::{
    Color, LineStrip3D, LineStrips3D, Points3D, Quaternion, Scalars, SeriesLines, TimeColumn,
    Transform3D,
};

use crate::Sink;

/// Chooses the frames to log at `hz` frames per simulated second: the first state at
/// or after every multiple of `1/hz` (and the first state of the run).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateGate {
    period_s: f64,
    next_s: f64,
}

impl RateGate {
    /// A gate at `hz` (> 0) starting at t = 0.
    pub fn new(hz: f64) -> Self {
        Self {
            period_s: 1.0 / hz,
            next_s: 0.0,
        }
    }

    /// True when the state at `time_s` is to be logged.
    pub fn due(&mut self, time_s: f64) -> bool {
        // Half a nanosecond of slack: times are sums of dt and land a rounding error
        // off the multiples of the period.
        if time_s + 5e-10 < self.next_s {
            return false;
        }
        let k = ((time_s + 5e-10) / self.period_s).floor() + 1.0;
        self.next_s = k * self.period_s;
        true
    }
}

/// Handle of a scalar series (or group of series) in [`Columns`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SeriesId(usize);
/// Handle of a pose channel in [`Columns`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TransformId(usize);
/// Handle of a line-strip channel in [`Columns`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StripsId(usize);
/// Handle of a channel of coloured points in [`Columns`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PointsId(usize);
/// Handle of a channel of strip colours (strips logged once, static) in [`Columns`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ColorsId(usize);

#[derive(Debug, Clone)]
enum Index {
    DurationS(Vec<f64>),
    Sequence(Vec<i64>),
}

#[derive(Debug, Clone)]
struct Series {
    entity: String,
    /// Scalars per frame (instances of the entity).
    width: usize,
    /// Names of the instances (logged once, static) for a group.
    names: Option<Vec<String>>,
    /// `width` values per frame, frame after frame.
    values: Vec<f64>,
}

#[derive(Debug, Clone)]
struct Strips {
    entity: String,
    radius_m: f32,
    /// Strips per frame.
    counts: Vec<usize>,
    /// Points per strip.
    lengths: Vec<usize>,
    /// Points of every strip, strip after strip.
    points: Vec<[f32; 3]>,
    colors: Vec<[u8; 4]>,
}

/// Wall-clock time between two sends when frames are sent as they come
/// ([`Columns::flush_when_due`]): a live viewer updates four times a second, and a
/// recording gets few, large chunks (each chunk has a fixed encoding cost).
const SEND_INTERVAL: Duration = Duration::from_millis(250);

/// Channels (scalar series and groups of series, poses, coloured line strips) filled
/// frame by frame and sent with `send_columns` by [`Columns::flush`]. Pushing a frame
/// costs a few vector pushes; every channel becomes one chunk per send.
#[derive(Debug, Clone)]
pub struct Columns {
    timeline: &'static str,
    index: Index,
    /// A second timeline of the same frames, in seconds ([`Columns::also_on_duration`]).
    second: Option<(&'static str, Vec<f64>)>,
    series: Vec<Series>,
    poses: Vec<(String, Vec<[f32; 3]>, Vec<[f32; 4]>)>,
    strips: Vec<Strips>,
    /// Points: the same layout as strips of one point each.
    points: Vec<Strips>,
    /// `(entity, colours per frame, colours)` of strips whose geometry is static.
    colors: Vec<(String, Vec<usize>, Vec<[u8; 4]>)>,
    last_send: Instant,
    names_sent: bool,
}

impl Strips {
    /// An empty channel of `radius_m` at `entity`.
    fn new(entity: impl Into<String>, radius_m: f64) -> Self {
        Self {
            entity: entity.into(),
            radius_m: radius_m as f32,
            counts: Vec::new(),
            lengths: Vec::new(),
            points: Vec::new(),
            colors: Vec::new(),
        }
    }
}

impl Columns {
    /// Channels indexed by a duration timeline `timeline` in seconds.
    pub fn on_duration(timeline: &'static str) -> Self {
        Self::with_index(timeline, Index::DurationS(Vec::new()))
    }

    /// Channels indexed by an integer sequence timeline `timeline`.
    pub fn on_sequence(timeline: &'static str) -> Self {
        Self::with_index(timeline, Index::Sequence(Vec::new()))
    }

    fn with_index(timeline: &'static str, index: Index) -> Self {
        Self {
            timeline,
            index,
            second: None,
            series: Vec::new(),
            poses: Vec::new(),
            strips: Vec::new(),
            points: Vec::new(),
            colors: Vec::new(),
            last_send: Instant::now(),
            names_sent: false,
        }
    }

    /// Adds a scalar series at `entity` (one value per frame, [`Columns::push`]).
    pub fn series(&mut self, entity: impl Into<String>) -> SeriesId {
        self.series.push(Series {
            entity: entity.into(),
            width: 1,
            names: None,
            values: Vec::new(),
        });
        SeriesId(self.series.len() - 1)
    }

    /// Adds a group of scalar series at `entity`, one instance per name (one value per
    /// name per frame, [`Columns::push_group`]). The viewer draws a line per instance
    /// under its name; a group is one chunk per send instead of one per series.
    pub fn series_group(&mut self, entity: impl Into<String>, names: Vec<String>) -> SeriesId {
        self.series.push(Series {
            entity: entity.into(),
            width: names.len(),
            names: Some(names),
            values: Vec::new(),
        });
        SeriesId(self.series.len() - 1)
    }

    /// Adds a pose (translation + rotation) channel at `entity`.
    pub fn pose(&mut self, entity: impl Into<String>) -> TransformId {
        self.poses.push((entity.into(), Vec::new(), Vec::new()));
        TransformId(self.poses.len() - 1)
    }

    /// Adds a channel of coloured line strips of `radius_m` at `entity`.
    pub fn strips(&mut self, entity: impl Into<String>, radius_m: f64) -> StripsId {
        self.strips.push(Strips::new(entity, radius_m));
        StripsId(self.strips.len() - 1)
    }

    /// Adds a channel of coloured points of `radius_m` at `entity`.
    pub fn points(&mut self, entity: impl Into<String>, radius_m: f64) -> PointsId {
        self.points.push(Strips::new(entity, radius_m));
        PointsId(self.points.len() - 1)
    }

    /// Adds a channel of the colours of the line strips at `entity`, whose geometry is
    /// logged once (static): a frame costs a colour per strip instead of its points.
    pub fn strip_colors(&mut self, entity: impl Into<String>) -> ColorsId {
        self.colors.push((entity.into(), Vec::new(), Vec::new()));
        ColorsId(self.colors.len() - 1)
    }

    /// The same channels, their frames also on the duration timeline `timeline` (give
    /// each frame its time there with [`Columns::also_at_s`]).
    pub fn also_on_duration(mut self, timeline: &'static str) -> Self {
        self.second = Some((timeline, Vec::new()));
        self
    }

    /// The current frame's time on the second timeline, s.
    pub fn also_at_s(&mut self, time_s: f64) {
        if let Some((_, t)) = &mut self.second {
            t.push(time_s);
        }
    }

    /// Starts a frame at `time_s` (duration timelines).
    pub fn frame_at_s(&mut self, time_s: f64) {
        match &mut self.index {
            Index::DurationS(t) => t.push(time_s),
            Index::Sequence(t) => t.push((time_s * 1e3).round() as i64),
        }
    }

    /// Starts a frame at step `k` (sequence timelines).
    pub fn frame_at(&mut self, k: i64) {
        match &mut self.index {
            Index::DurationS(t) => t.push(k as f64),
            Index::Sequence(t) => t.push(k),
        }
    }

    /// Room for `frames` more frames in every channel of fixed width (index, series,
    /// poses, strip colours), so that a long run's buffers grow once.
    pub fn reserve(&mut self, frames: usize) {
        match &mut self.index {
            Index::DurationS(t) => t.reserve(frames),
            Index::Sequence(t) => t.reserve(frames),
        }
        for s in &mut self.series {
            s.values.reserve(frames * s.width);
        }
        for (_, t, q) in &mut self.poses {
            t.reserve(frames);
            q.reserve(frames);
        }
        for (_, counts, _) in &mut self.colors {
            counts.reserve(frames);
        }
    }

    /// Frames buffered since the last flush.
    pub fn frames(&self) -> usize {
        match &self.index {
            Index::DurationS(t) => t.len(),
            Index::Sequence(t) => t.len(),
        }
    }

    /// The value of series `id` in the current frame.
    pub fn push(&mut self, id: SeriesId, value: f64) {
        self.series[id.0].values.push(value);
    }

    /// The values of group `id` in the current frame, in the order of its names.
    pub fn push_group(&mut self, id: SeriesId, values: impl IntoIterator<Item = f64>) {
        self.series[id.0].values.extend(values);
    }

    /// The pose of channel `id` in the current frame: translation (m) and rotation
    /// quaternion `[x, y, z, w]`.
    pub fn push_pose(&mut self, id: TransformId, translation_m: [f64; 3], quat_xyzw: [f64; 4]) {
        let p = &mut self.poses[id.0];
        p.1.push(translation_m.map(|v| v as f32));
        p.2.push(quat_xyzw.map(|v| v as f32));
    }

    /// The strips of channel `id` in the current frame, each with its colour.
    pub fn push_strips<I, P>(&mut self, id: StripsId, strips: I)
    where
        I: IntoIterator<Item = (P, [u8; 4])>,
        P: IntoIterator<Item = [f64; 3]>,
    {
        let s = &mut self.strips[id.0];
        let mut n = 0;
        for (points, color) in strips {
            let before = s.points.len();
            s.points
                .extend(points.into_iter().map(|p| p.map(|v| v as f32)));
            s.lengths.push(s.points.len() - before);
            s.colors.push(color);
            n += 1;
        }
        s.counts.push(n);
    }

    /// The points of channel `id` in the current frame, each with its colour.
    pub fn push_points(
        &mut self,
        id: PointsId,
        points: impl IntoIterator<Item = ([f64; 3], [u8; 4])>,
    ) {
        let s = &mut self.points[id.0];
        let before = s.points.len();
        for (p, color) in points {
            s.points.push(p.map(|v| v as f32));
            s.colors.push(color);
        }
        s.counts.push(s.points.len() - before);
    }

    /// The colours of the strips of channel `id` in the current frame, in their order.
    pub fn push_colors(&mut self, id: ColorsId, colors: impl IntoIterator<Item = [u8; 4]>) {
        let (_, counts, all) = &mut self.colors[id.0];
        let before = all.len();
        all.extend(colors);
        counts.push(all.len() - before);
    }

    fn time_columns(&self) -> Vec<TimeColumn> {
        let mut out = vec![match &self.index {
            Index::DurationS(t) => TimeColumn::new_duration_secs(self.timeline, t.clone()),
            Index::Sequence(t) => TimeColumn::new_sequence(self.timeline, t.clone()),
        }];
        if let Some((name, t)) = &self.second {
            out.push(TimeColumn::new_duration_secs(*name, t.clone()));
        }
        out
    }

    /// [`Columns::flush`] when a quarter of a second (wall clock) has passed since the
    /// last send: call it after every frame of a long run.
    pub fn flush_when_due(&mut self, rec: &Sink) {
        if self.last_send.elapsed() >= SEND_INTERVAL {
            self.flush(rec);
        }
    }

    /// Sends every buffered frame to `rec` and empties the buffers (keeping the
    /// channels). A channel that missed a frame is a bug: it is reported, not sent.
    pub fn flush(&mut self, rec: &Sink) {
        self.last_send = Instant::now();
        let n = self.frames();
        if n == 0 {
            return;
        }
        if rec.is_enabled() {
            self.send(rec, n);
        }
        match &mut self.index {
            Index::DurationS(t) => t.clear(),
            Index::Sequence(t) => t.clear(),
        }
        if let Some((_, t)) = &mut self.second {
            t.clear();
        }
        for s in &mut self.series {
            s.values.clear();
        }
        for (_, t, q) in &mut self.poses {
            t.clear();
            q.clear();
        }
        for s in self.strips.iter_mut().chain(&mut self.points) {
            s.counts.clear();
            s.lengths.clear();
            s.points.clear();
            s.colors.clear();
        }
        for (_, counts, colors) in &mut self.colors {
            counts.clear();
            colors.clear();
        }
    }

    fn send(&mut self, rec: &Sink, n: usize) {
        let stream = rec.stream();
        if !self.names_sent {
            // Once per recording, static: series names and strip radii (one radius for
            // every strip of a channel at every time).
            self.names_sent = true;
            for s in &self.strips {
                rec.report(
                    &s.entity,
                    stream.log_static(
                        s.entity.as_str(),
                        &LineStrips3D::update_fields().with_radii([s.radius_m]),
                    ),
                );
            }
            for s in &self.points {
                rec.report(
                    &s.entity,
                    stream.log_static(
                        s.entity.as_str(),
                        &Points3D::update_fields().with_radii([s.radius_m]),
                    ),
                );
            }
            for s in &self.series {
                if let Some(names) = &s.names {
                    rec.report(
                        &s.entity,
                        stream.log_static(
                            s.entity.as_str(),
                            &SeriesLines::new().with_names(names.iter().map(String::as_str)),
                        ),
                    );
                }
            }
        }
        let time = self.time_columns();
        if time.iter().any(|t| t.num_rows() != n) {
            rec.report(
                self.timeline,
                Err::<(), _>(format!("a second timeline missed frames ({n} frames)")),
            );
            return;
        }
        // Sends one channel's columns as a chunk, or reports why it cannot (once).
        let send = |entity: &str, frames: usize, columns: Result<Vec<_>, String>| {
            let sent = if frames == n {
                columns.and_then(|c| {
                    let chunk = time_ordered_chunk(entity, &time, c).map_err(|e| e.to_string())?;
                    stream.send_chunk(chunk);
                    Ok(())
                })
            } else {
                Err(format!("{frames} entries for {n} frames"))
            };
            rec.report(entity, sent);
        };
        let err = |e: rerun::SerializationError| e.to_string();
        for s in self.series.iter().filter(|s| s.width > 0) {
            let cols = Scalars::new(s.values.iter().copied())
                .columns(std::iter::repeat_n(s.width, s.values.len() / s.width));
            send(
                &s.entity,
                s.values.len() / s.width,
                cols.map(Iterator::collect).map_err(err),
            );
        }
        for (entity, tr, q) in &self.poses {
            let cols = Transform3D::update_fields()
                .with_many_quaternion(
                    q.iter()
                        .map(|q| RotationQuat::from(Quaternion::from_xyzw(*q))),
                )
                .with_many_translation(tr.iter().map(|t| Translation3D::from(*t)))
                .columns_of_unit_batches();
            send(entity, q.len(), cols.map(Iterator::collect).map_err(err));
        }
        for s in &self.strips {
            let mut at = 0;
            let strips = s.lengths.iter().map(|&len| {
                let strip = LineStrip3D::from_iter(s.points[at..at + len].iter().copied());
                at += len;
                strip
            });
            let cols = LineStrips3D::update_fields()
                .with_strips(strips)
                .with_colors(s.colors.iter().map(rgba))
                .columns(s.counts.iter().copied());
            send(
                &s.entity,
                s.counts.len(),
                cols.map(Iterator::collect).map_err(err),
            );
        }
        for s in &self.points {
            let cols = Points3D::update_fields()
                .with_positions(s.points.iter().copied())
                .with_colors(s.colors.iter().map(rgba))
                .columns(s.counts.iter().copied());
            send(
                &s.entity,
                s.counts.len(),
                cols.map(Iterator::collect).map_err(err),
            );
        }
        for (entity, counts, colors) in &self.colors {
            let cols = LineStrips3D::update_fields()
                .with_colors(colors.iter().map(rgba))
                .columns(counts.iter().copied());
            send(
                entity,
                counts.len(),
                cols.map(Iterator::collect).map_err(err),
            );
        }
    }
}

/// A chunk of `columns` at `entity`, one row per entry of `time`, whose rows are in
/// the order of `time` (frames are pushed in time order). `send_columns` would sort
/// the rows by time first: for a chunk of ten thousand rows that sort, comparing
/// through a map lookup, cost as much as serialising the data.
fn time_ordered_chunk(
    entity: &str,
    time: &[TimeColumn],
    columns: Vec<SerializedComponentColumn>,
) -> Result<Chunk, rerun::log::ChunkError> {
    let id = ChunkId::new();
    Chunk::new(
        id,
        entity.into(),
        Some(true),
        row_ids_after(id, time.first().map_or(0, TimeColumn::num_rows)),
        time.iter()
            .map(|t| (*t.timeline().name(), t.clone()))
            .collect(),
        columns.into_iter().collect(),
    )
}

/// `n` row ids following the chunk id `id`, as Rerun's own `send_columns` makes them,
/// as the arrow column of a chunk: each id's 16 bytes (time, then counter, big-endian)
/// written straight into one buffer (Rerun's `RowId::arrow_from_slice` goes through a
/// generic per-value builder that cost a fifth of the logging thread).
fn row_ids_after(id: ChunkId, n: usize) -> FixedSizeBinaryArray {
    let mut bytes = Vec::with_capacity(16 * n);
    let mut row = RowId::from_tuid((*id).next());
    for _ in 0..n {
        bytes.extend_from_slice(&row.as_tuid().as_bytes());
        row = row.next();
    }
    FixedSizeBinaryArray::new(16, Buffer::from_vec(bytes), None)
}

/// A colour of the frame buffers (`[r, g, b, a]`, not premultiplied) as Rerun's.
fn rgba(c: &[u8; 4]) -> Color {
    Color::from_unmultiplied_rgba(c[0], c[1], c[2], c[3])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_gate_picks_one_state_per_period_from_a_fine_grid() {
        let mut g = RateGate::new(60.0);
        let dt = 1e-3;
        let picked: Vec<usize> = (0..=1000).filter(|&i| g.due(i as f64 * dt)).collect();
        // t = 0, then the first step at or after k/60 s for k = 1..60.
        assert_eq!(picked.len(), 61);
        assert_eq!(picked[0], 0);
        assert_eq!(picked[1], 17); // 1/60 = 16.67 ms
        assert_eq!(picked[60], 1000);
        for w in picked.windows(2) {
            assert!((16..=17).contains(&(w[1] - w[0])), "{w:?}");
        }
        // A coarse grid logs every state.
        let mut g = RateGate::new(60.0);
        assert!((0..10).all(|i| g.due(i as f64 * 0.1)));
    }

    #[test]
    fn row_ids_are_rerun_s_own_column_of_increasing_ids() {
        let id = ChunkId::new();
        let ours = row_ids_after(id, 1000);
        let ids: Vec<RowId> =
            std::iter::successors(Some(RowId::from_tuid((*id).next())), |r| Some(r.next()))
                .take(1000)
                .collect();
        assert_eq!(ours, RowId::arrow_from_slice(&ids));
        assert!(ids.windows(2).all(|w| w[0] < w[1]));
        assert!(ids[0].as_tuid() > *id);
    }

    #[test]
    fn flushing_empties_the_buffers_and_keeps_the_channels() {
        let mut c = Columns::on_duration("sim_time");
        let a = c.series("/a");
        let p = c.pose("/p");
        let s = c.strips("/s", 0.01);
        for k in 0..3 {
            c.frame_at_s(k as f64);
            c.push(a, k as f64);
            c.push_pose(p, [0.0; 3], [0.0, 0.0, 0.0, 1.0]);
            c.push_strips(s, [([[0.0; 3], [1.0; 3]], [1, 2, 3, 255])]);
        }
        assert_eq!(c.frames(), 3);
        c.flush(crate::Recorder::off().sink());
        assert_eq!(c.frames(), 0);
        c.frame_at_s(4.0);
        c.push(a, 1.0);
        assert_eq!(c.frames(), 1);
    }
}
