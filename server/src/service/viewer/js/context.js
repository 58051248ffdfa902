// The WebGL2 context of the canvas and the renderer's programs and GPU
// sets over it (gl.js). A browser without WebGL2 stops the script here.
import { canvas, body, say } from './dom.js';
import { createRenderer } from './gl.js';

export const gl = canvas.getContext('webgl2', { antialias: true, preserveDrawingBuffer: true });
if (!gl) {
  body.dataset.state = 'error';
  say('This browser has no WebGL2.');
  throw new Error('no WebGL2');
}
export const renderer = createRenderer(gl);
const { shaded, flat, wide, pickProgram, buffer, wideLines, pointSet, free } = renderer;
export { shaded, flat, wide, pickProgram, buffer, wideLines, pointSet, free };
