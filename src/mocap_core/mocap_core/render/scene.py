"""CPU rendering of a posed body in a randomised scene with pyrender + OSMesa (no ROS).

:class:`Appearance` holds what varies between clips (clothing colours per body region, skin,
floor and background textures, lights); :func:`sample_appearance` draws one from a seed.
:class:`SceneRenderer` renders frames of one clip: the static scene (floor, four textured
walls, lights) is built once, the body mesh is replaced per frame, and the OSMesa renderer is
recreated every :data:`RENDERER_REFRESH_FRAMES` frames (its memory grows ~7 MB per frame
otherwise; ``../shared/ENVIRONMENT.md``).

Camera convention: the pose given per frame is the optical frame (x right, y down, z forward)
in the world: ``R`` world -> camera rows, ``position`` the centre (as
:class:`mocap_core.data.synth2d.VirtualCamera`). pyrender's camera looks along -z with y up,
so its pose is ``[R^T diag(1, -1, -1) | position]``.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import RendererUnavailable

#: Frames rendered before the OSMesa renderer is recreated (bounds its memory growth).
RENDERER_REFRESH_FRAMES = 32

_SKIN_TONES = ((0.96, 0.80, 0.69), (0.90, 0.70, 0.56), (0.78, 0.57, 0.44), (0.62, 0.43, 0.31),
               (0.45, 0.30, 0.22), (0.33, 0.22, 0.16))
_TEXTURES = ('checker', 'stripes', 'tiles', 'noise', 'gradient', 'plain')


@dataclass
class Appearance:
    """What a camera sees besides the motion (all colours RGB in [0, 1]).

    Attributes:
        colours: body region (``body.BONE_REGIONS`` values) -> colour.
        floor: (texture kind, colour a, colour b, tile size m).
        walls: (texture kind, colour a, colour b, tile size m).
        sky: background colour.
        light_direction: (3,) unit vector the sun shines along (world).
        light_intensity: directional light intensity.
        ambient: ambient light level.
        headlight: intensity of the light at the camera.
    """

    colours: Dict[str, Tuple[float, float, float]]
    floor: Tuple[str, Tuple[float, ...], Tuple[float, ...], float]
    walls: Tuple[str, Tuple[float, ...], Tuple[float, ...], float]
    sky: Tuple[float, float, float]
    light_direction: Tuple[float, float, float]
    light_intensity: float
    ambient: float
    headlight: float = 2.0

    def to_dict(self) -> dict:
        return asdict(self)


def _colour(rng: np.random.Generator, lo: float = 0.05, hi: float = 0.95) -> Tuple[float, ...]:
    return tuple(float(x) for x in rng.uniform(lo, hi, 3))


def sample_appearance(rng: np.random.Generator) -> Appearance:
    """Random clothing (shirt with short or long sleeves, trousers or shorts, shoes), skin,
    floor, walls, sky and light."""
    skin = tuple(float(c) * rng.uniform(0.9, 1.1) for c in
                 _SKIN_TONES[rng.integers(len(_SKIN_TONES))])
    skin = tuple(min(1.0, c) for c in skin)
    shirt, trousers, shoes = _colour(rng), _colour(rng), _colour(rng, 0.02, 0.6)
    long_sleeves, long_legs = rng.random() < 0.6, rng.random() < 0.75
    colours = {
        'head': skin, 'neck': skin, 'hand': skin, 'trunk': shirt, 'upper_arm': shirt,
        'forearm': shirt if long_sleeves else skin, 'hips': trousers, 'thigh': trousers,
        'shin': trousers if long_legs else skin, 'foot': shoes, 'hair': _colour(rng, 0.02, 0.5),
    }
    az, el = rng.uniform(0, 2 * np.pi), rng.uniform(np.radians(25), np.radians(80))
    direction = -np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])

    def texture():
        return (str(_TEXTURES[rng.integers(len(_TEXTURES))]), _colour(rng), _colour(rng),
                float(rng.uniform(0.25, 1.5)))

    return Appearance(colours, texture(), texture(), _colour(rng, 0.3, 1.0),
                      tuple(float(x) for x in direction), float(rng.uniform(2.5, 6.0)),
                      float(rng.uniform(0.3, 0.8)), float(rng.uniform(1.5, 3.5)))


def texture_image(kind: str, a: Sequence[float], b: Sequence[float], size: int = 256,
                  seed: int = 0) -> np.ndarray:
    """(size, size, 3) uint8 tile of one texture kind (one tile repeats over ``tile`` m)."""
    a, b = np.asarray(a) * 255, np.asarray(b) * 255
    y, x = np.mgrid[0:size, 0:size] / size
    if kind == 'checker':
        m = ((x < 0.5) ^ (y < 0.5)).astype(float)
    elif kind == 'stripes':
        m = (x < 0.5).astype(float)
    elif kind == 'tiles':
        m = ((x % 0.5 < 0.04) | (y % 0.5 < 0.04)).astype(float)
    elif kind == 'noise':
        rng = np.random.default_rng(seed)
        coarse = rng.random((8, 8))
        m = coarse[(y * 8).astype(int) % 8, (x * 8).astype(int) % 8]
    elif kind == 'gradient':
        m = y
    else:
        m = np.zeros_like(x)
    img = a * (1 - m[..., None]) + b * m[..., None]
    return np.clip(img, 0, 255).astype(np.uint8)


def _import_pyrender():
    """pyrender with OSMesa (or EGL when ``PYOPENGL_PLATFORM=egl``), or a clear error."""
    os.environ.setdefault('PYOPENGL_PLATFORM', 'osmesa')
    if not hasattr(np, 'infty'):  # pyrender 0.1.45 still uses the alias numpy 2 removed
        np.infty = np.inf
    try:
        import pyrender
        from OpenGL import GL  # noqa: F401 - fails here when the platform library is missing
    except ImportError as exc:
        raise RendererUnavailable(
            f'pyrender is not installed ({exc}); run scripts/setup.sh, which installs '
            'requirements/render.txt') from None
    except Exception as exc:  # noqa: BLE001 - OpenGL raises several types for a missing lib
        raise RendererUnavailable(
            f'OpenGL platform {os.environ["PYOPENGL_PLATFORM"]!r} unavailable '
            f'({type(exc).__name__}: {exc}); install the OSMesa library (Debian: apt-get '
            'install libosmesa6; scripts/setup.sh does it when run as root) or set '
            'PYOPENGL_PLATFORM=egl') from None
    return pyrender


def check_renderer() -> Optional[str]:
    """None when a 16x16 test image renders, else the reason it does not."""
    try:
        pyrender = _import_pyrender()
        scene = pyrender.Scene(bg_color=[0.5, 0.5, 0.5, 1.0])
        r = pyrender.OffscreenRenderer(16, 16)
        try:
            scene.add(pyrender.PerspectiveCamera(yfov=1.0), pose=np.eye(4))
            r.render(scene)
        finally:
            r.delete()
    except RendererUnavailable as exc:
        return str(exc)
    except Exception as exc:  # noqa: BLE001 - a context that cannot be created, etc.
        return (f'rendering fails ({type(exc).__name__}: {exc}); on Debian install '
                'libosmesa6 (scripts/setup.sh does it when run as root)')
    return None


#: Colours of the head's features (``body.head_detail_regions``) that are not drawn per clip.
EYE_IRIS, EYE_WHITE = (0.12, 0.08, 0.05), (0.88, 0.87, 0.84)


#: Natural hair colours (black, dark brown, brown, auburn, dark blond, blond, grey).
HAIR_TONES = ((0.05, 0.04, 0.035), (0.14, 0.09, 0.06), (0.28, 0.18, 0.11), (0.40, 0.17, 0.08),
              (0.52, 0.40, 0.24), (0.78, 0.66, 0.44), (0.62, 0.61, 0.60))


def hair_tone(drawn: Sequence[float]) -> Tuple[float, float, float]:
    """A natural hair colour picked from :data:`HAIR_TONES` by the clip's drawn ``hair``
    colour (three numbers in [0.02, 0.5]: the first picks the tone, the second its shade), so
    that renders of the same seed differ only in the head."""
    t = HAIR_TONES[min(len(HAIR_TONES) - 1, int((drawn[0] - 0.02) / 0.48 * len(HAIR_TONES)))]
    shade = 0.85 + 0.3 * (drawn[1] - 0.02) / 0.48
    return tuple(float(min(1.0, c * shade)) for c in t)


def head_detail_colours(appearance: Appearance) -> Dict[str, Tuple[float, float, float]]:
    """Region -> colour of the head's features: hair and eyebrows in the clip's hair colour
    (the brows darker), the lips a darker, redder skin, the eyes fixed."""
    hair = hair_tone(appearance.colours.get('hair', (0.1, 0.08, 0.06)))
    skin = tuple(appearance.colours.get('head', (0.8, 0.6, 0.5)))
    return {'hair': hair, 'brow': tuple(0.7 * c for c in hair),
            'lips': (0.85 * skin[0], 0.6 * skin[1], 0.6 * skin[2]),
            'eye_iris': EYE_IRIS, 'eye_white': EYE_WHITE}


def vertex_colours(appearance: Appearance, regions: Sequence[str]) -> np.ndarray:
    """(V, 4) float32 RGBA of each vertex from its body region's colour (clothing, skin, and
    the head's features of :func:`head_detail_colours`)."""
    ap = appearance
    colours = {**ap.colours, **head_detail_colours(ap)}
    return np.array([list(colours.get(r, ap.colours['trunk'])) + [1.0] for r in regions],
                    dtype=np.float32)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit vertex normals (area-weighted face normals summed per vertex)."""
    v = vertices.astype(np.float64)
    fn = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    return (n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)).astype(np.float32)


def optical_to_gl(R: np.ndarray, position: np.ndarray) -> np.ndarray:
    """(4, 4) pyrender camera pose from a world -> optical rotation and a centre."""
    pose = np.eye(4)
    pose[:3, :3] = np.asarray(R).T @ np.diag([1.0, -1.0, -1.0])
    pose[:3, 3] = position
    return pose


@dataclass
class SceneRenderer:
    """Renders one clip's frames (see the module docstring).

    Args:
        width, height: image size, pixels.
        K: (3, 3) intrinsics.
        faces: (T, 3) body triangles; regions: per vertex region name.
        appearance: clothing, floor, walls, light.
        centre: (2,) world xy the room is centred on (the clip's mean position).
        room: half size of the room, metres.
    """

    width: int
    height: int
    K: np.ndarray
    faces: np.ndarray
    regions: List[str]
    appearance: Appearance
    centre: np.ndarray = field(default_factory=lambda: np.zeros(2))
    room: float = 25.0

    def __post_init__(self) -> None:
        self._pr = _import_pyrender()
        pr = self._pr
        ap = self.appearance
        self.scene = pr.Scene(bg_color=list(ap.sky) + [1.0], ambient_light=[ap.ambient] * 3)
        self._add_room()
        light = np.eye(4)
        d = np.asarray(ap.light_direction)
        z = -d / np.linalg.norm(d)  # a pyrender light shines along its -z
        x = np.cross([0.0, 0.0, 1.0], z)
        x = x / max(np.linalg.norm(x), 1e-9) if np.linalg.norm(x) > 1e-6 else np.array([1, 0, 0])
        light[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
        self.scene.add(pr.DirectionalLight(color=np.ones(3), intensity=ap.light_intensity),
                       pose=light)
        fill = light.copy()
        fill[:3, :3] = np.diag([-1.0, -1.0, 1.0]) @ light[:3, :3]
        self.scene.add(pr.DirectionalLight(color=np.ones(3), intensity=ap.light_intensity * 0.3),
                       pose=fill)
        K = self.K
        self._camera = pr.IntrinsicsCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], znear=0.05,
                                           zfar=200.0)
        self._camera_node = self.scene.add(self._camera, pose=np.eye(4))
        # A light at the camera (shining where it looks) so that a back-lit body is not black.
        self._headlight = self.scene.add(
            pr.DirectionalLight(color=np.ones(3), intensity=ap.headlight), pose=np.eye(4))
        self._colours = vertex_colours(ap, self.regions)
        self._material = pr.MetallicRoughnessMaterial(metallicFactor=0.0, roughnessFactor=0.8,
                                                      baseColorFactor=[1.0, 1.0, 1.0, 1.0])
        self._body_nodes: list = []
        self._renderer = None
        self._frames = 0

    def _textured_quad(self, corners: np.ndarray, kind, a, b, tile: float, seed: int):
        pr = self._pr
        size = np.linalg.norm(corners[1] - corners[0]), np.linalg.norm(corners[3] - corners[0])
        uv = np.array([[0, 0], [size[0] / tile, 0], [size[0] / tile, size[1] / tile],
                       [0, size[1] / tile]], dtype=np.float32)
        n = np.cross(corners[1] - corners[0], corners[3] - corners[0])
        n = np.tile(n / np.linalg.norm(n), (4, 1)).astype(np.float32)
        tex = pr.Texture(source=texture_image(kind, a, b, seed=seed), source_channels='RGB',
                         sampler=pr.Sampler(wrapS=10497, wrapT=10497))  # GL_REPEAT
        mat = pr.MetallicRoughnessMaterial(baseColorTexture=tex, metallicFactor=0.0,
                                           roughnessFactor=0.9)
        prim = pr.Primitive(positions=corners.astype(np.float32), normals=n, texcoord_0=uv,
                            indices=np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32),
                            material=mat)
        self.scene.add(pr.Mesh([prim]))

    def _add_room(self) -> None:
        ap = self.appearance
        cx, cy = self.centre
        s = self.room
        floor = np.array([[cx - s, cy - s, 0], [cx + s, cy - s, 0], [cx + s, cy + s, 0],
                          [cx - s, cy + s, 0]], dtype=np.float64)
        self._textured_quad(floor, *ap.floor, seed=1)
        h = 12.0
        for k, (p0, p1) in enumerate(zip(floor, np.roll(floor, -1, axis=0))):
            # walls face inwards: corners ordered so the normal points to the centre
            wall = np.array([p1, p0, p0 + [0, 0, h], p1 + [0, 0, h]])
            self._textured_quad(wall, *ap.walls, seed=2 + k)

    def render(self, vertices: np.ndarray, R: np.ndarray, position: np.ndarray) -> np.ndarray:
        """(H, W, 3) uint8 **BGR** image of the body ``vertices`` (V, 3) from the camera
        (``R`` world -> optical, ``position``)."""
        return self.render_bodies([(vertices, self._colours)], R, position)

    def render_bodies(self, bodies: Sequence[Tuple[np.ndarray, np.ndarray]], R: np.ndarray,
                      position: np.ndarray) -> np.ndarray:
        """As :meth:`render`, several bodies in one image: ``(vertices (V, 3), colours (V, 4)
        RGBA float32)`` each (:func:`vertex_colours`), all with this renderer's faces."""
        pr = self._pr
        if self._renderer is None or self._frames % RENDERER_REFRESH_FRAMES == 0:
            if self._renderer is not None:
                self._renderer.delete()
            self._renderer = pr.OffscreenRenderer(self.width, self.height)
        self._frames += 1
        for node in self._body_nodes:
            self.scene.remove_node(node)
        self._body_nodes = []
        for vertices, colours in bodies:
            prim = pr.Primitive(positions=vertices.astype(np.float32),
                                normals=vertex_normals(vertices, self.faces),
                                color_0=colours, indices=self.faces.astype(np.uint32),
                                material=self._material)
            self._body_nodes.append(self.scene.add(pr.Mesh([prim])))
        self.scene.set_pose(self._camera_node, optical_to_gl(R, position))
        self.scene.set_pose(self._headlight, optical_to_gl(R, position))
        rgb, _ = self._renderer.render(self.scene)
        return np.ascontiguousarray(rgb[..., ::-1])

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.delete()
            self._renderer = None
