// Draw GLB files with three.js in headless Chromium: node tests/support/three_render.js JOBS.json
//
// JOBS.json: {"three": DIR (the npm package `three`), "chromium": PATH, "jobs": [{"glb": PATH,
//   "out": PATH.png, "width": W, "height": H, "camera": K, "clear": "#ff00ff",
//   "plugin": PATH.js or null}, ...]}
// Each job: GLTFLoader (with the plugin's default export registered, if given) loads the file; the
// file's K-th camera draws it (aspect W / H) into a canvas with outputColorSpace = SRGB, no tone
// mapping, no antialiasing, preserveDrawingBuffer; the canvas is written as an 8-bit PNG.
// Prints one JSON line: [{"out": ..., "warnings": [console warnings and errors], "materials":
//   [three.js material types], "attempts": n, "blank": whether the canvas stayed blank}, ...]
// (a blank canvas is drawn again, at most three times); exit 0, or 2 with the error on stderr.
// Needs puppeteer-core on the module path (NODE_PATH, see the Makefile); the browser side is
// browser_jobs.js, shared with babylon_render.js.
"use strict";
const { main } = require("./browser_jobs.js");

const PAGE = `<!doctype html><html><body style="margin:0">
<script type="importmap">{"imports": {"three": "/three/build/three.module.js",
  "three/addons/": "/three/examples/jsm/"}}</script>
<script type="module">
import * as THREE from "three";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
window.renderJob = async (job) => {
  const canvas = document.createElement("canvas");
  canvas.width = job.width; canvas.height = job.height;
  document.body.appendChild(canvas);
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setSize(job.width, job.height, false);
  renderer.outputColorSpace = THREE.SRGBColorSpace;
  renderer.toneMapping = THREE.NoToneMapping;
  renderer.setClearColor(new THREE.Color(job.clear), 1.0);
  const loader = new GLTFLoader();
  if (job.plugin) {
    const mod = await import(job.plugin);
    loader.register((parser) => mod.default(parser));
  }
  const gltf = await loader.loadAsync(job.glb);
  const camera = gltf.cameras[job.camera];
  if (!camera) throw new Error("the file has " + gltf.cameras.length + " camera(s), not " + (job.camera + 1));
  camera.aspect = job.width / job.height;
  camera.updateProjectionMatrix();
  gltf.scene.updateMatrixWorld(true);
  renderer.render(gltf.scene, camera);
  const types = new Set();
  gltf.scene.traverse((o) => { if (o.material) types.add(o.material.type + (o.material.lightMap ? "+lightMap" : "")); });
  const out = window.canvasResult(canvas, renderer.getContext(), types);
  renderer.dispose();
  canvas.remove();
  return out;
};
window.ready = true;
</script></body></html>`;

main(PAGE, (spec) => ({ three: spec.three }));
