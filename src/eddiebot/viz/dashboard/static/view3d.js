// eddie dashboard 3D view: point clouds (RTAB-Map's cloud map, the Kinect's /points) with
// three.js, loaded only when the view is opened. Drag: orbit; shift-drag: pan; wheel: zoom.
import * as THREE from "./vendor/three.module.min.js";

export function open(container, robotPose) {
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x1d1f21);
  const camera = new THREE.PerspectiveCamera(60, 1, 0.05, 500);
  camera.up.set(0, 0, 1);
  const orbit = { target: new THREE.Vector3(), dist: 8, az: -Math.PI / 2, el: 0.9 };
  const p = robotPose();
  if (p) orbit.target.set(p.x, p.y, 0);
  scene.add(new THREE.AxesHelper(1));
  const grid = new THREE.GridHelper(40, 40, 0x555555, 0x333333);
  grid.rotation.x = Math.PI / 2;
  scene.add(grid);
  const clouds = {};
  let renderer = null;
  let error = null;
  try {
    renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
    renderer.setPixelRatio(1);
    container.append(renderer.domElement);
  } catch (e) {
    error = "3D view needs WebGL: " + (e && e.message ? e.message : e);
    const msg = document.createElement("div");
    msg.className = "view3d-error"; msg.textContent = error;
    container.append(msg);
  }
  let dirty = true;
  let raf = 0;
  let drawn = 0;

  function place() {
    const c = Math.cos(orbit.el);
    camera.position.set(orbit.target.x + orbit.dist * c * Math.cos(orbit.az),
      orbit.target.y + orbit.dist * c * Math.sin(orbit.az), orbit.target.z + orbit.dist * Math.sin(orbit.el));
    camera.lookAt(orbit.target);
  }
  function render() {
    raf = 0;
    if (!renderer) return;
    const w = container.clientWidth, h = container.clientHeight;
    const size = renderer.getSize(new THREE.Vector2());
    if (size.x !== w || size.y !== h) { renderer.setSize(w, h, false); camera.aspect = w / Math.max(1, h); camera.updateProjectionMatrix(); }
    place();
    renderer.render(scene, camera);
    drawn = renderer.info.render.points;
    dirty = false;
  }
  function request() { dirty = true; if (!raf) raf = requestAnimationFrame(render); }

  function setCloud(head, payload) {
    const n = head.n;
    const xyz = new Float32Array(payload, 0, n * 3);
    const geom = new THREE.BufferGeometry();
    geom.setAttribute("position", new THREE.BufferAttribute(xyz.slice(), 3));
    const colours = new Float32Array(n * 3);
    if (head.rgb) {
      const rgb = new Uint8Array(payload, n * 12, n * 3);
      for (let i = 0; i < n * 3; i++) colours[i] = rgb[i] / 255;
    } else {  // colour by height, 0 .. 2 m
      const c = new THREE.Color();
      for (let i = 0; i < n; i++) {
        c.setHSL(0.7 * (1 - Math.min(1, Math.max(0, xyz[i * 3 + 2] / 2))), 0.9, 0.5);
        colours[i * 3] = c.r; colours[i * 3 + 1] = c.g; colours[i * 3 + 2] = c.b;
      }
    }
    geom.setAttribute("color", new THREE.BufferAttribute(colours, 3));
    const old = clouds[head.name];
    if (old) { scene.remove(old); old.geometry.dispose(); old.material.dispose(); }
    const pts = new THREE.Points(geom, new THREE.PointsMaterial({ size: 2, sizeAttenuation: false, vertexColors: true }));
    pts.name = head.name;
    clouds[head.name] = pts;
    scene.add(pts);
    request();
  }

  let drag = null;
  const el = renderer ? renderer.domElement : container;
  el.addEventListener("mousedown", (e) => { drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey }; e.preventDefault(); });
  window.addEventListener("mouseup", () => { drag = null; });
  el.addEventListener("mousemove", (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX; drag.y = e.clientY;
    if (drag.pan) {
      // grab the ground: right on screen is (-sin az, cos az), away is (-cos az, -sin az)
      const k = orbit.dist * 0.002, s = Math.sin(orbit.az), c = Math.cos(orbit.az);
      orbit.target.x += k * (dx * s - dy * c);
      orbit.target.y += k * (-dx * c - dy * s);
    } else {
      orbit.az -= dx * 0.006;
      orbit.el = Math.min(1.55, Math.max(-0.2, orbit.el + dy * 0.006));
    }
    request();
  });
  el.addEventListener("wheel", (e) => {
    e.preventDefault();
    orbit.dist = Math.min(200, Math.max(0.5, orbit.dist * Math.exp(e.deltaY * 0.0015)));
    request();
  }, { passive: false });
  const resize = new ResizeObserver(request);
  resize.observe(container);
  request();

  return {
    setCloud,
    error: () => error,
    // points drawn by the last rendered frame (points held when WebGL is missing)
    drawn: () => renderer ? drawn : Object.values(clouds).reduce((a, c) => a + c.geometry.attributes.position.count, 0),
    close() {
      resize.disconnect();
      if (raf) cancelAnimationFrame(raf);
      for (const c of Object.values(clouds)) { c.geometry.dispose(); c.material.dispose(); }
      if (renderer) { renderer.dispose(); renderer.forceContextLoss(); }
      container.textContent = "";
    },
  };
}
