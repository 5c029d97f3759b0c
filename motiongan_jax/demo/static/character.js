// The 3-D character view: the GLB that /api/export writes (the same file the GLB button
// downloads), drawn by three.js from the npm package installed beside this page
// (package.json, package-lock.json; the import map in index.html points at node_modules).
// One skinned instance per motion (its own animation), lit by a sun that casts shadows on the floor.
import * as THREE from "three";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
import * as SkeletonUtils from "three/addons/utils/SkeletonUtils.js";

export const version = THREE.REVISION;

export function createView(canvas) {
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  renderer.shadowMap.enabled = true;
  renderer.shadowMap.type = THREE.PCFSoftShadowMap;
  renderer.setScissorTest(true);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x141a28);
  scene.fog = new THREE.Fog(0x141a28, 14, 45);
  scene.add(new THREE.HemisphereLight(0xdde6ff, 0x2a2418, 1.1));
  const sun = new THREE.DirectionalLight(0xffffff, 2.2);
  sun.castShadow = true;
  sun.shadow.mapSize.set(2048, 2048);
  Object.assign(sun.shadow.camera, { left: -3, right: 3, top: 3, bottom: -3, near: 0.5, far: 20 });
  sun.shadow.bias = -0.0005;
  scene.add(sun, sun.target);
  const floor = new THREE.Mesh(new THREE.PlaneGeometry(400, 400),
                               new THREE.MeshStandardMaterial({ color: 0x2a3142, roughness: 0.95 }));
  floor.rotation.x = -Math.PI / 2;
  floor.receiveShadow = true;
  scene.add(floor);
  const grid = new THREE.GridHelper(400, 400, 0x55607a, 0x3a4358);
  grid.position.y = 0.001;
  scene.add(grid);
  let path = null;
  let instances = [];
  const camera = new THREE.PerspectiveCamera(40, 1, 0.05, 200);
  const loader = new GLTFLoader();

  function setPath(curve) {  // [[x, z], ...] metres
    if (path) { scene.remove(path); path.geometry.dispose(); }
    const pts = curve.map(([x, z]) => new THREE.Vector3(x, 0.004, z));
    path = new THREE.Line(new THREE.BufferGeometry().setFromPoints(pts),
                          new THREE.LineBasicMaterial({ color: 0xff7a59 }));
    scene.add(path);
  }

  async function load(buffer) {
    const gltf = await loader.parseAsync(buffer, "");
    for (const it of instances) scene.remove(it.root);
    instances = gltf.animations.map((clip) => {
      const root = SkeletonUtils.clone(gltf.scene);
      let meshes = 0;
      root.traverse((o) => {
        if (o.isMesh) { o.castShadow = true; o.frustumCulled = false; meshes++; }
      });
      const mixer = new THREE.AnimationMixer(root);
      mixer.clipAction(clip).play();
      scene.add(root);
      return { root, mixer, meshes, clip: clip.name };
    });
    return { animations: instances.map((i) => i.clip), meshes: instances.reduce((a, i) => a + i.meshes, 0) };
  }

  // the steered walker: the GLB's body without its animation, its joints (`names`, the server's
  // "joints") turned each frame by pose(); returns what load() does
  async function loadPosed(buffer, names) {
    const gltf = await loader.parseAsync(buffer, "");
    for (const it of instances) scene.remove(it.root);
    const root = gltf.scene;
    let meshes = 0;
    root.traverse((o) => { if (o.isMesh) { o.castShadow = true; o.frustumCulled = false; meshes++; } });
    // the loader's node names: three's PropertyBinding.sanitizeNodeName
    const bones = names.map((n) => root.getObjectByName(THREE.PropertyBinding.sanitizeNodeName(n)) || null);
    const missing = names.filter((n, i) => !bones[i]);
    if (missing.length) throw new Error(`the GLB has no joint ${missing.slice(0, 3).join(", ")}`);
    scene.add(root);
    instances = [{ root, mixer: null, meshes, clip: "steer", bones }];
    return { animations: [], meshes };
  }

  // rotations qa, qb ([x, y, z, w] per joint, local) and roots ra, rb of two samples, blended at a
  const qA = new THREE.Quaternion(), qB = new THREE.Quaternion();
  function pose(qa, qb, a, ra, rb) {
    const it = instances[0];
    if (!it || !it.bones) return;
    it.bones.forEach((bone, j) => {
      qA.fromArray(qa[j]); qB.fromArray(qb[j]);
      bone.quaternion.slerpQuaternions(qA, qB, a);
    });
    it.bones[0].position.set(ra[0] + a * (rb[0] - ra[0]), ra[1] + a * (rb[1] - ra[1]), ra[2] + a * (rb[2] - ra[2]));
  }

  // panels: [{x, y, w, h, index, eye: [x, y, z], target: [x, y, z]}] in CSS pixels of the canvas
  function render(panels, time, width, height, dpr) {
    renderer.setPixelRatio(dpr);
    if (canvas.width !== Math.round(width * dpr) || canvas.height !== Math.round(height * dpr)) {
      renderer.setSize(width, height, false);
    }
    for (const p of panels) {
      instances.forEach((it, i) => { it.root.visible = i === p.index; });
      const it = instances[p.index];
      if (it && it.mixer) it.mixer.setTime(time);
      const [tx, ty, tz] = p.target;
      sun.position.set(tx + 2.5, 6, tz + 1.5);
      sun.target.position.set(tx, 0, tz);
      camera.aspect = p.w / p.h;
      camera.position.set(...p.eye);
      camera.lookAt(tx, ty, tz);
      camera.updateProjectionMatrix();
      const y = height - p.y - p.h;  // WebGL counts from the bottom
      renderer.setViewport(p.x, y, p.w, p.h);
      renderer.setScissor(p.x, y, p.w, p.h);
      renderer.render(scene, camera);
    }
  }

  return { load, loadPosed, pose, render, setPath, get count() { return instances.length; } };
}
