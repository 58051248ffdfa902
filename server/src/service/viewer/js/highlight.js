// What a warning or a refused binding is about, as the server describes it
// (viewer.rs, `Highlight`): segments (drawn from the current pose's
// samples), spline polylines, markers, faces; a box to frame. One colour,
// used for nothing else: violet.
import { indexSegments } from './math.js';

/** The highlight colour (RGBA). */
export const HIGHLIGHT = [0.62, 0.36, 1.0, 1];

/**
 * GPU sets of `highlights` in `pose` ({ points, nets: [{ samples }] }):
 * per highlight its lines, its markers and its faces (indexed into the pose's points).
 */
export function buildHighlights(r, highlights, pose) {
  return highlights.map((h) => {
    const lines = Array.from(h.lines);
    for (let j = 0; j + 2 < h.sample_segments.length; j += 3) {
      const [k, a, b] = [h.sample_segments[j], h.sample_segments[j + 1], h.sample_segments[j + 2]];
      const net = pose.nets[k];
      if (net) lines.push(...indexSegments(net.samples, [a, b]));
    }
    return {
      lines: r.wideLines(lines),
      points: r.pointSet(h.points),
      faces: h.triangles.length ? r.pointSet(pose.points, h.triangles) : null,
    };
  });
}

/** Writes what `h` names onto `el`'s data attributes (for scripts and tests). */
export function describe(el, h) {
  el.dataset.code = h.code;
  el.dataset.element = h.element;
  const set = (key, value) => {
    if (value === undefined || value === null || value === '') delete el.dataset[key];
    else el.dataset[key] = String(value);
  };
  const seg = h.segments[0];
  set('curvenet', seg ? seg.curvenet : h.curvenet);
  set('spline', seg ? seg.spline : h.splines[0]);
  set('segment', seg ? seg.segment : null);
  set('segments', h.segments.map((s) => `${s.curvenet}:${s.spline}:${s.segment}`).join(' '));
  set('sample', h.sample);
  set('controlPoint', h.control_point);
  set('faces', h.faces.join(','));
  set('vertices', h.vertices.join(','));
}

/** A short label of what `h` names. */
export function label(h) {
  const seg = (s) => `curvenet ${s.curvenet} spline ${s.spline} segment ${s.segment}`;
  switch (h.element) {
    case 'segment': return h.segments.map(seg).join(' and ');
    case 'sample': return `curvenet ${h.curvenet} sample ${h.sample}${h.splines.length ? ` (spline ${h.splines[0]})` : ''}`;
    case 'spline': return `curvenet ${h.curvenet ?? '?'} spline${h.splines.length > 1 ? 's' : ''} ${h.splines.join(', ')}`;
    case 'control_point': return `curvenet ${h.curvenet ?? '?'} control point ${h.control_point}`;
    case 'faces': return `face${h.faces.length > 1 ? 's' : ''} ${h.faces.slice(0, 12).join(', ')}${h.faces.length > 12 ? ', …' : ''}`;
    case 'vertices': return `vertices ${h.vertices.slice(0, 12).join(', ')}`;
    default: return 'nothing to point at';
  }
}

/**
 * A refused stage (a ViewerRefusal) in the shape of the viewer's data: the
 * mesh, no cut-mesh, each curvenet as its samples (or, when it could not be
 * sampled, its Bézier polylines), no frames, and the error's highlight.
 */
export function refusalData(r) {
  const curvenets = r.curvenets.map((c) => {
    if (c.samples.length) {
      return { samples: c.samples, segments: c.segments, intersections: [], anchors: [], removed_samples: [], far_samples: [], frames: [] };
    }
    const segments = [];
    for (let s = 0; s + 1 < c.spline_start.length; s++) {
      for (let i = c.spline_start[s]; i + 1 < c.spline_start[s + 1]; i++) segments.push(i, i + 1);
    }
    return { samples: c.points, segments, intersections: [], anchors: [], removed_samples: [], far_samples: [], frames: [] };
  });
  return {
    refused: r,
    binding: null,
    diagonal: r.diagonal,
    mesh: r.mesh,
    cut: { points: [], mask: [], edges: [], edge_kind: [], face_start: [0], face_vertices: [], face_parent: [] },
    curvenets,
    warnings: [],
    highlights: [r.highlight],
  };
}
