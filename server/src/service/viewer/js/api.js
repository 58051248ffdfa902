// Access to the service's viewer endpoints: the bearer token (from
// #token=, the session, or the panel) and one fetch wrapper whose errors
// carry the service's error code.

const hashParams = new URLSearchParams(location.hash.slice(1));
export let token = hashParams.get('token') || sessionStorage.getItem('curvenet-token') || '';

export class ApiError extends Error {
  constructor(status, code, message) {
    super(code ? `${code}: ${message}` : message);
    this.status = status;
    this.code = code;
  }
}

export async function api(path, options = {}) {
  const headers = Object.assign({}, options.headers || {});
  if (token) headers.Authorization = `Bearer ${token}`;
  const response = await fetch(path, Object.assign({}, options, { headers }));
  const text = await response.text();
  let json = null;
  try { json = JSON.parse(text); } catch (_) { /* not JSON */ }
  if (!response.ok) {
    if (response.status === 401) document.getElementById('token-form').hidden = false;
    throw new ApiError(response.status, json && json.code, (json && json.message) || `HTTP ${response.status} for ${path}`);
  }
  return json;
}

/** Sets the bearer token (remembered for the session). */
export function setToken(value) {
  token = value;
  sessionStorage.setItem('curvenet-token', token);
}
