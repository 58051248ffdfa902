// The page's elements and its message line: the leaf every other module
// of the script may use.

export const $ = (id) => document.getElementById(id);
export const canvas = $('view');
export const body = document.body;

export function say(text) { $('message').textContent = text || ''; }

/** Marks the page failed (data-state="error") and says why. */
export function fail(e) {
  body.dataset.state = 'error';
  say(e.message || String(e));
  console.error(e);
}
