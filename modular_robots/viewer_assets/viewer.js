// The winner's motion: the scene from the page's JSON, a player (play/pause, time slider) and
// orbit/zoom controls. The base frame is z-up, in metres. window.viewer is for scripts and tests.
(function () {
  "use strict";
  const S = JSON.parse(document.getElementById("scene-data").textContent);
  const host = document.getElementById("view");
  const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  host.appendChild(renderer.domElement);

  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xf4f5f7);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8899aa, 0.75));
  const sun = new THREE.DirectionalLight(0xffffff, 0.65);
  sun.position.set(3, -2, 5);
  scene.add(sun);

  // the extent of everything drawn, to place the camera and the floor grid
  const waypoints = S.waypoints || [];
  const points = [[0, 0, 0]].concat(S.tool, S.start ? [S.start] : [], S.goal ? [S.goal] : [], waypoints);
  S.obstacles.forEach((o) => points.push(o.center));
  const box = new THREE.Box3().setFromPoints(points.map((p) => new THREE.Vector3(p[0], p[1], p[2])));
  const centre = box.getCenter(new THREE.Vector3());
  const radius = Math.max(0.5, box.getSize(new THREE.Vector3()).length() / 2 + 0.3);

  const camera = new THREE.PerspectiveCamera(40, 1, 0.01, 100);
  camera.up.set(0, 0, 1);
  camera.position.set(centre.x + 1.6 * radius, centre.y - 2.0 * radius, centre.z + 1.2 * radius);
  const controls = new THREE.OrbitControls(camera, renderer.domElement);
  controls.target.copy(centre);
  controls.update();

  const grid = new THREE.GridHelper(2 * Math.ceil(radius + 1), 2 * Math.ceil(radius + 1), 0xb0b4ba, 0xd5d8dc);
  grid.rotation.x = Math.PI / 2;
  scene.add(grid);
  scene.add(new THREE.AxesHelper(0.3));

  function material(color, extra) {
    return new THREE.MeshStandardMaterial(Object.assign({ color: color, roughness: 0.6, metalness: 0.1 }, extra || {}));
  }
  function sphere(r, mat, at) {
    const mesh = new THREE.Mesh(new THREE.SphereGeometry(r, 32, 16), mat);
    if (at) mesh.position.set(at[0], at[1], at[2]);
    return mesh;
  }

  // a shape in the page's vocabulary (links and obstacles alike), posed by its column-major origin
  function shapePart(shape, mat) {
    const part = new THREE.Group();
    part.matrixAutoUpdate = false;
    part.matrix.fromArray(shape.origin);
    if (shape.type === "capsule") {
      const body = new THREE.Mesh(new THREE.CylinderGeometry(shape.radius, shape.radius, shape.length, 32), mat);
      body.rotation.x = Math.PI / 2; // three's cylinder runs along y, URDF's along z
      part.add(body);
      part.add(sphere(shape.radius, mat, [0, 0, shape.length / 2]));
      part.add(sphere(shape.radius, mat, [0, 0, -shape.length / 2]));
    } else if (shape.type === "cylinder") {
      const body = new THREE.Mesh(new THREE.CylinderGeometry(shape.radius, shape.radius, shape.length, 32), mat);
      body.rotation.x = Math.PI / 2;
      part.add(body);
    } else if (shape.type === "sphere") {
      part.add(sphere(shape.radius, mat));
    } else if (shape.type === "box") {
      part.add(new THREE.Mesh(new THREE.BoxGeometry(shape.size[0], shape.size[1], shape.size[2]), mat));
    } else if (shape.type === "mesh") {
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute("position", new THREE.Float32BufferAttribute(shape.vertices.flat(), 3));
      geometry.setIndex(shape.faces.flat());
      geometry.computeVertexNormals();
      part.add(new THREE.Mesh(geometry, mat));
    }
    return part;
  }

  const solid = material(0xd9534f, { transparent: true, opacity: 0.6 });
  const shell = new THREE.MeshBasicMaterial({ color: 0xd9534f, wireframe: true, transparent: true, opacity: 0.2 });
  S.obstacles.forEach((o) => {
    o.parts.forEach((shape) => scene.add(shapePart(shape, solid)));
    o.shell.forEach((shape) => scene.add(shapePart(shape, shell)));
  });
  if (S.start) scene.add(sphere(0.035, material(0x16a34a), S.start));
  if (S.goal) scene.add(sphere(0.035, material(0x222222), S.goal));
  waypoints.forEach((p) => scene.add(sphere(0.03, material(0x2563eb), p)));
  const path = new THREE.BufferGeometry().setFromPoints(S.tool.map((p) => new THREE.Vector3(p[0], p[1], p[2])));
  scene.add(new THREE.Line(path, new THREE.LineBasicMaterial({ color: 0x333333 })));

  // one group per URDF link, posed by the frame's matrix; shapes in the link frame
  const links = S.links.map((link) => {
    const group = new THREE.Group();
    group.matrixAutoUpdate = false;
    const mat = material(link.color);
    link.shapes.forEach((shape) => {
      // a port sphere 2 % larger than the capsule ends it meets: no z-fighting
      const drawn = shape.type === "sphere" ? Object.assign({}, shape, { radius: 1.02 * shape.radius }) : shape;
      group.add(shapePart(drawn, mat));
    });
    scene.add(group);
    return group;
  });

  const slider = document.getElementById("time");
  const clock = document.getElementById("clock");
  const button = document.getElementById("play");
  let t = 0;
  let playhead = 0; // runs a second past tf (the goal is held), then loops
  let playing = true;
  let last = null;

  function setTime(time) {
    t = Math.min(Math.max(time, 0), S.tf);
    const k = Math.round((t / S.tf) * (S.frames.length - 1));
    links.forEach((group, i) => {
      group.matrix.fromArray(S.frames[k][i]);
      group.matrixWorldNeedsUpdate = true;
    });
    slider.value = String(Math.round((1000 * t) / S.tf));
    clock.textContent = t.toFixed(3) + " / " + S.tf.toFixed(3) + " s";
  }
  function setPlaying(on) {
    playing = on;
    playhead = t;
    button.textContent = on ? "Pause" : "Play";
    last = null;
  }
  button.addEventListener("click", () => {
    if (!playing && t >= S.tf) setTime(0);
    setPlaying(!playing);
  });
  slider.addEventListener("input", () => {
    setPlaying(false);
    setTime((Number(slider.value) / 1000) * S.tf);
  });

  function resize() {
    const w = host.clientWidth || 1;
    const h = host.clientHeight || 1;
    renderer.setSize(w, h);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
  }
  window.addEventListener("resize", resize);
  resize();

  function frame(now) {
    if (playing) {
      if (last !== null) {
        playhead += (now - last) / 1000;
        if (playhead > S.tf + 1) playhead = 0;
        setTime(playhead);
      }
      last = now;
    }
    controls.update();
    renderer.render(scene, camera);
    requestAnimationFrame(frame);
  }
  setTime(0);
  requestAnimationFrame(frame);

  window.viewer = {
    tf: S.tf,
    frames: S.frames.length,
    setTime: (time) => {
      setPlaying(false);
      setTime(time);
      renderer.render(scene, camera);
    },
    play: () => setPlaying(true),
    ready: true,
  };
})();
