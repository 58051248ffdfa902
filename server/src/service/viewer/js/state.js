// What the page shows: the source, its data and frames, the pose, the
// layers, the picks and the user's adjustments. Plain state, no behaviour.

export const view = {
  source: null,       // { kind: 'stage', index } or { kind: 'binding', id }
  data: null,         // ViewerData
  times: [],          // frame time codes (stage) or [null] (binding)
  frames: new Map(),  // frame index -> ViewerFrame
  frame: 0,
  pose: 'deformed',
  picked: -1,
  boxScale: 1,
  layers: { shaded: true, wire: false, cut: true, curvenet: true, frames: true, problems: true, knots: true, cage: true },
  selected: -1,       // the highlight (warning) clicked in the panel, framed
  gpu: null,          // static GPU objects of the binding
  dyn: null,          // GPU objects of the current pose
  dynKey: '',
  playing: false,
  generation: 0,      // bumps on every source change (stale fetches are dropped)
  knot: null,         // the picked knot: { curvenet, knot } (pool index)
  user: new Map(),    // frame index -> Map(knotKey -> AdjustmentSpec): the user's adjustments
  serial: 0,          // bumps with every frame fetched (the pose's GPU key)
  adjusted: 0,        // frames drawn with the user's adjustments (data-adjusted)
};

/** The user's adjustments at frame `k`, as the service takes them. */
export function userSpecs(k) {
  const m = view.user.get(k);
  return m ? Array.from(m.values()) : [];
}
