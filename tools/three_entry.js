// The three.js classes the report player uses (src/meshmocap/apps/report/assets/player.js),
// bundled into src/meshmocap/apps/report/assets/three.min.js by tools/build_three.sh.
export {
  AmbientLight, AnimationMixer, BufferAttribute, BufferGeometry, Color, DirectionalLight,
  Float32BufferAttribute, GridHelper, Group, HemisphereLight, LineBasicMaterial, LineSegments,
  Mesh, MeshStandardMaterial, Points, PointsMaterial, PerspectiveCamera, Scene, SphereGeometry,
  InstancedMesh, MeshBasicMaterial, Matrix4, Object3D, Vector3, Box3, WebGLRenderer,
  SRGBColorSpace, DoubleSide, CircleGeometry, MeshLambertMaterial, REVISION,
} from "three";
export { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
export { OrbitControls } from "three/addons/controls/OrbitControls.js";
