"""The camera observation model against OpenCV, an implementation nobody here wrote.

`project` and its derivatives against ``cv2.projectPoints`` (pixels and its own Jacobian)
and central differences; the checkerboard's corner order against ``cv2.findChessboardCorners``
on rendered images; the simulated pixels against ``cv2.projectPoints`` of the composed
transforms.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import casecal as cc
from casecal.observations.camera import (
    INTRINSIC_NAMES,
    Intrinsics,
    in_front,
    jacobian_intrinsics,
    jacobian_point,
    project,
    radially_monotonic,
)
from casecal.observations.simulate import (
    CameraSetup,
    board_tilt,
    inverse,
    look_at,
    points_in_camera,
    select_views,
    simulate_pixels,
    visible,
)
from casecal.observations.target import Checkerboard

cv2 = pytest.importorskip("cv2")


def random_intrinsics(rng) -> Intrinsics:
    """A realistic camera: 1280 × 1024, focal 800-2000 px, distortion of a real lens."""
    f = rng.uniform(800, 2000)
    return Intrinsics(
        fx=f,
        fy=f * rng.uniform(0.98, 1.02),
        cx=rng.uniform(600, 680),
        cy=rng.uniform(480, 540),
        k1=rng.uniform(-0.4, 0.2),
        k2=rng.uniform(-0.2, 0.3),
        p1=rng.uniform(-2e-3, 2e-3),
        p2=rng.uniform(-2e-3, 2e-3),
        k3=rng.uniform(-0.1, 0.1),
    )


def random_points(rng, n: int) -> np.ndarray:
    """Points in front of the camera within a ±0.5 normalised field (x/z, y/z), m."""
    z = rng.uniform(0.2, 3.0, n)
    return np.stack([rng.uniform(-0.5, 0.5, n) * z, rng.uniform(-0.5, 0.5, n) * z, z], 1)


def cv2_project(intr: Intrinsics, X, rvec=None, tvec=None):
    K, dist = intr.to_opencv()
    rvec = np.zeros(3) if rvec is None else rvec
    tvec = np.zeros(3) if tvec is None else tvec
    uv, J = cv2.projectPoints(np.asarray(X, float).reshape(-1, 1, 3), rvec, tvec, K, dist)
    return uv.reshape(-1, 2), J.reshape(-1, 2, J.shape[1])


# --- project and its derivatives ---------------------------------------------------------


@pytest.mark.parametrize("seed", range(5))
def test_project_matches_opencv(seed):
    rng = np.random.default_rng(seed)
    intr = random_intrinsics(rng)
    p = random_points(rng, 500)
    ours = project(intr, p)
    theirs, _ = cv2_project(intr, p)
    assert np.abs(ours - theirs).max() < 1e-9


@pytest.mark.parametrize("seed", range(5))
def test_point_jacobian_matches_opencv(seed):
    """OpenCV's columns for tvec are ∂(u, v)/∂p at p = R(rvec) X + tvec (∂p/∂tvec = I)."""
    rng = np.random.default_rng(100 + seed)
    intr = random_intrinsics(rng)
    p = random_points(rng, 300)
    # with rvec = tvec = 0, p itself; and a general rvec/tvec by the chain rule above
    _, J0 = cv2_project(intr, p)
    scale = np.abs(J0[:, :, 3:6]).max()
    assert np.abs(jacobian_point(intr, p) - J0[:, :, 3:6]).max() < 1e-12 * scale
    rvec, tvec = rng.normal(0, 0.3, 3), np.array([0.05, -0.02, 0.3])
    R = cv2.Rodrigues(rvec)[0]
    X = (p - tvec) @ R  # so that R X + tvec = p
    uv, J = cv2_project(intr, X, rvec, tvec)
    assert np.abs(uv - project(intr, p)).max() < 1e-9
    assert np.abs(jacobian_point(intr, p) - J[:, :, 3:6]).max() < 1e-12 * scale


@pytest.mark.parametrize("seed", range(5))
def test_intrinsics_jacobian_matches_opencv(seed):
    """OpenCV's columns 6-14: fx, fy, cx, cy, then k1 k2 p1 p2 k3, our order."""
    rng = np.random.default_rng(200 + seed)
    intr = random_intrinsics(rng)
    p = random_points(rng, 300)
    _, J = cv2_project(intr, p)
    ours = jacobian_intrinsics(intr, p)
    for k, name in enumerate(INTRINSIC_NAMES):
        col = J[:, :, 6 + k]
        tol = 1e-12 * max(1.0, np.abs(col).max())
        assert np.abs(ours[:, :, k] - col).max() < tol, name


@pytest.mark.parametrize("seed", range(3))
def test_jacobians_match_central_differences(seed):
    rng = np.random.default_rng(300 + seed)
    intr = random_intrinsics(rng)
    p = random_points(rng, 100)
    h = 1e-6
    fd = np.stack(
        [(project(intr, p + h * e) - project(intr, p - h * e)) / (2 * h) for e in np.eye(3)], -1
    )
    Jp = jacobian_point(intr, p)
    assert np.abs(Jp - fd).max() < 1e-6 * np.abs(Jp).max()
    v = intr.vector()
    steps = np.array([1e-3, 1e-3, 1e-3, 1e-3, 1e-7, 1e-7, 1e-7, 1e-7, 1e-7])
    fd = np.stack(
        [
            (
                project(Intrinsics.from_vector(v + s * e), p)
                - project(Intrinsics.from_vector(v - s * e), p)
            )
            / (2 * s)
            for s, e in zip(steps, np.eye(9), strict=True)
        ],
        -1,
    )
    Ji = jacobian_intrinsics(intr, p)
    for k, name in enumerate(INTRINSIC_NAMES):
        assert np.abs(Ji[:, :, k] - fd[:, :, k]).max() < 1e-6 * max(1, np.abs(Ji[:, :, k]).max()), (
            name
        )


@pytest.mark.parametrize("z", [0.0, -0.5, -1e-12, np.nan])
@pytest.mark.parametrize("fn", [project, jacobian_point, jacobian_intrinsics, radially_monotonic])
def test_points_behind_the_camera_are_refused(fn, z):
    intr = Intrinsics(1000, 1000, 640, 512, k1=-0.2)
    p = np.array([[0.1, 0.0, 1.0], [0.1, 0.2, z], [0.0, 0.0, 2.0]])
    with pytest.raises(cc.CalibrationError, match=r"not in front|not finite"):
        fn(intr, p)
    assert in_front(np.array([[0, 0, 1.0], [0, 0, 0.0], [0, 0, -1.0]])).tolist() == [
        True,
        False,
        False,
    ]


def test_points_of_a_wrong_shape_are_refused():
    with pytest.raises(cc.CalibrationError, match=r"\(N, 3\)"):
        project(Intrinsics(1000, 1000, 640, 512), np.ones(3))


def test_radially_monotonic_is_where_the_distorted_radius_still_grows():
    """Against the distorted radius r·(1 + k1 r² + k2 r⁴ + k3 r⁶) sampled on a fine grid."""
    intr = Intrinsics(1000, 1000, 640, 512, k1=-0.3, k2=0.02, k3=0.0)
    r = np.linspace(0.01, 2.0, 2000)
    rd = r * (1 + intr.k1 * r**2 + intr.k2 * r**4)
    grows = np.gradient(rd, r) > 0
    mono = radially_monotonic(intr, np.stack([r, 0 * r, np.ones_like(r)], 1))
    # the grid's derivative and ours agree away from the one turning point
    turn = np.flatnonzero(np.diff(grows.astype(int)))
    assert len(turn) == 1
    keep = np.abs(np.arange(len(r)) - turn[0]) > 2
    assert np.array_equal(mono[keep], grows[keep])


# --- Intrinsics ---------------------------------------------------------------------------


def test_intrinsics_round_trip_through_opencv():
    rng = np.random.default_rng(7)
    intr = random_intrinsics(rng)
    K, dist = intr.to_opencv()
    assert Intrinsics.from_opencv(K, dist) == intr
    assert Intrinsics.from_opencv(K, dist.reshape(1, 5)) == intr
    # OpenCV's 8-, 12- and 14-coefficient vectors with the extra terms zero, and 4 without k3
    for n in (8, 12, 14):
        assert Intrinsics.from_opencv(K, np.r_[dist, np.zeros(n - 5)]) == intr
    four = Intrinsics.from_opencv(K, dist[:4])
    assert four.k3 == 0 and four.k1 == intr.k1
    assert Intrinsics.from_opencv(K) == Intrinsics(intr.fx, intr.fy, intr.cx, intr.cy)
    assert Intrinsics.from_vector(intr.vector()) == intr
    # a camera matrix OpenCV made: calibrateCamera's result is accepted as it comes
    K2, dist2 = Intrinsics.from_opencv(K, dist).to_opencv()
    assert np.array_equal(K2, K) and np.array_equal(dist2, dist)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"fx": 0.0}, "fx"),
        ({"fy": -800.0}, "fy"),
        ({"cx": np.nan}, "cx"),
        ({"k1": np.inf}, "k1"),
        ({"p2": "a"}, "p2"),
    ],
)
def test_bad_intrinsics_are_refused(kwargs, match):
    values = {"fx": 1000.0, "fy": 1000.0, "cx": 640.0, "cy": 512.0} | kwargs
    with pytest.raises(cc.CalibrationError, match=match):
        Intrinsics(**values)


@pytest.mark.parametrize(
    ("K", "dist", "match"),
    [
        (np.eye(2), None, "shape"),
        ([[1000, 1, 640], [0, 1000, 512], [0, 0, 1]], None, "skew"),
        ([[1000, 0, 640], [0, 1000, 512], [0, 0, 2]], None, "form"),
        ([[1000, 0, 640], [0, 1000, 512], [0, 0, 1]], [0.1, 0.0, 0.0], "distortion"),
        ([[1000, 0, 640], [0, 1000, 512], [0, 0, 1]], [0.1, 0, 0, 0, 0, 0.2, 0, 0], "rational"),
        ([[-1000, 0, 640], [0, 1000, 512], [0, 0, 1]], None, "fx"),
    ],
)
def test_bad_opencv_calibrations_are_refused(K, dist, match):
    with pytest.raises(cc.CalibrationError, match=match):
        Intrinsics.from_opencv(K, dist)


# --- the checkerboard -----------------------------------------------------------------------


def test_checkerboard_corners_convention():
    board = Checkerboard(rows=7, cols=9, spacing=0.02)
    c = board.corners()
    assert c.shape == (63, 3) and board.pattern_size == (9, 7)
    # OpenCV's tutorial object points: np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * spacing
    objp = np.mgrid[0:9, 0:7].T.reshape(-1, 2) * 0.02
    assert np.array_equal(c[:, :2], objp) and not c[:, 2].any()
    assert c[10].tolist() == [0.02, 0.02, 0.0]  # row 1, column 1
    assert np.allclose(board.centre, c.mean(axis=0))
    assert board.symmetric and not Checkerboard(6, 9).symmetric and Checkerboard(5, 5).symmetric


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"rows": 1}, "rows"), ({"cols": 2.5}, "cols"), ({"spacing": 0}, "spacing"),
     ({"spacing": np.nan}, "spacing"), ({"rows": True}, "rows")],
)  # fmt: skip
def test_bad_checkerboards_are_refused(kwargs, match):
    with pytest.raises(cc.CalibrationError, match=match):
        Checkerboard(**kwargs)


def render_board(intr: Intrinsics, T_cam_board, board: Checkerboard, size, ss=2) -> np.ndarray:
    """An 8-bit image of the board on white paper (no distortion), `ss`² samples a pixel.

    The square diagonally outside corner 0 (around (−s/2, −s/2)) is black, and so every
    square (i, j) with i + j even, i and j counting squares from that one.
    """
    w, h = size
    us = (np.arange(w * ss) + 0.5) / ss - 0.5
    vs = (np.arange(h * ss) + 0.5) / ss - 0.5
    U, V = np.meshgrid(us, vs)
    d = np.stack([(U - intr.cx) / intr.fx, (V - intr.cy) / intr.fy, np.ones_like(U)], -1)
    R, t = T_cam_board[:3, :3], T_cam_board[:3, 3]
    n = R[:, 2]
    pb = ((n @ t) / (d @ n))[..., None] * d - t
    pb = pb @ R  # the ray's hit on the board plane, board frame
    i = np.floor(pb[..., 1] / board.spacing) + 1
    j = np.floor(pb[..., 0] / board.spacing) + 1
    on = (i >= 0) & (i <= board.rows) & (j >= 0) & (j <= board.cols)
    img = np.where(on & ((i + j) % 2 == 0), 0.0, 255.0)
    return img.reshape(h, ss, w, ss).mean(axis=(1, 3)).astype(np.uint8)


@pytest.mark.parametrize(
    ("rows", "cols", "turn"),
    [(6, 9, 0.5), (6, 9, 2.5), (7, 8, -2.0), (7, 9, 0.5), (7, 9, 2.5)],
)
def test_corner_order_matches_find_chessboard_corners(rows, cols, turn):
    """A board rendered at a known pose, detected by OpenCV: its corners in our order.

    With rows + cols odd the colours fix the order, and OpenCV's is ours at any turn of
    the board; with rows + cols even (symmetric) OpenCV's is ours or reversed (k → n−1−k):
    which one depends on the turn, not on the board — what a fit has to resolve.
    """
    intr = Intrinsics(800, 800, 320, 240)
    board = Checkerboard(rows, cols, 0.02)
    c, s = math.cos(turn), math.sin(turn)
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.array([0.3, -0.2, 0.0]))[0] @ [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = [0.0, 0.0, 0.45] - T[:3, :3] @ board.centre  # board's middle on the axis
    img = render_board(intr, T, board, (640, 480))
    found, det = cv2.findChessboardCorners(img, board.pattern_size)
    assert found
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    det = cv2.cornerSubPix(img, det, (5, 5), (-1, -1), criteria).reshape(-1, 2)
    uv = project(intr, board.corners() @ T[:3, :3].T + T[:3, 3])
    same, reversed_ = np.abs(det - uv).max(), np.abs(det[::-1] - uv).max()
    if board.symmetric:
        assert min(same, reversed_) < 0.5  # px: a rendered, antialiased image
        assert max(same, reversed_) > 50
    else:
        assert same < 0.5


# --- simulated data -------------------------------------------------------------------------

PUMA_Q0 = np.array([0.3, -0.6, 0.4, 0.2, 0.7, -0.3])
LENS = Intrinsics(1400, 1390, 650, 500, k1=-0.2, k2=0.1, p1=5e-4, p2=-3e-4, k3=-0.02)


def eye_in_hand_setup(robot) -> CameraSetup:
    """Camera 5 cm out on the flange looking along the tool's z; board square to it 0.5 m
    away at PUMA_Q0."""
    board = Checkerboard()
    X = np.eye(4)
    X[:3, :3] = cv2.Rodrigues(np.array([0.0, 0.0, 0.3]))[0]
    X[:3, 3] = [0.03, 0.0, 0.05]
    cam = robot.fk(PUMA_Q0) @ X
    B = cam.copy()
    B[:3, 3] = cam[:3, 3] + 0.5 * cam[:3, 2] - cam[:3, :3] @ board.centre
    return CameraSetup("eye_in_hand", X, B, LENS, board)


def eye_to_hand_setup(robot) -> CameraSetup:
    """Board 10 cm out on the flange; camera 1 m in front of it at PUMA_Q0."""
    board = Checkerboard()
    G = np.eye(4)
    G[:3, 3] = [0.0, 0.0, 0.1]
    bw = robot.fk(PUMA_Q0) @ G
    centre = bw[:3, :3] @ board.centre + bw[:3, 3]
    C = look_at(centre - 1.0 * bw[:3, 2], centre)
    return CameraSetup("eye_to_hand", C, G, LENS, board)


@pytest.fixture(scope="module")
def puma():
    return cc.load_robot("puma560")


@pytest.mark.parametrize("make", [eye_in_hand_setup, eye_to_hand_setup])
def test_simulated_pixels_match_opencv(puma, make):
    """Noise-free pixels against cv2.projectPoints with rvec/tvec of T_cam←target composed
    here from the robot's fk and the setup's poses."""
    setup = make(puma)
    q = select_views(puma, 8, setup, seed=3, q_centre=PUMA_Q0, spread=0.15)
    uv = simulate_pixels(puma, q, setup)
    assert uv.shape == (8, 63, 2)
    K, dist = setup.intrinsics.to_opencv()
    for qi, uvi in zip(q, uv, strict=True):
        T = puma.fk(qi)
        if setup.mode == "eye_in_hand":
            M = np.linalg.inv(T @ setup.camera) @ setup.target
        else:
            M = np.linalg.inv(setup.camera) @ T @ setup.target
        rvec = cv2.Rodrigues(M[:3, :3])[0]
        theirs, _ = cv2.projectPoints(setup.board.corners(), rvec, M[:3, 3], K, dist)
        assert np.abs(uvi - theirs.reshape(-1, 2)).max() < 1e-8


def test_simulated_noise_is_gaussian_and_repeats(puma):
    setup = eye_in_hand_setup(puma)
    q = select_views(puma, 20, setup, seed=4, q_centre=PUMA_Q0, spread=0.15)
    clean = simulate_pixels(puma, q, setup)
    noisy = simulate_pixels(puma, q, setup, sigma_px=0.5, seed=11)
    e = (noisy - clean).ravel()  # 2520 draws
    assert abs(e.std() - 0.5) < 0.05 and abs(e.mean()) < 0.05
    assert np.array_equal(noisy, simulate_pixels(puma, q, setup, sigma_px=0.5, seed=11))
    assert not np.array_equal(noisy, simulate_pixels(puma, q, setup, sigma_px=0.5, seed=12))
    with pytest.raises(cc.CalibrationError, match="seed"):
        simulate_pixels(puma, q, setup, sigma_px=0.5)
    with pytest.raises(cc.CalibrationError, match="sigma_px"):
        simulate_pixels(puma, q, setup, sigma_px=-1.0, seed=1)


@pytest.mark.parametrize("make", [eye_in_hand_setup, eye_to_hand_setup])
def test_selected_views_see_the_whole_board(puma, make):
    setup = make(puma)
    tilt = math.radians(45)
    q = select_views(puma, 25, setup, seed=5, q_centre=PUMA_Q0, spread=0.3, max_tilt=tilt)
    assert q.shape == (25, 6)
    assert np.all((q >= puma.limits[:, 0]) & (q <= puma.limits[:, 1]))
    p = points_in_camera(puma, q, setup)
    assert np.all(p[..., 2] > 0)
    uv = project(setup.intrinsics, p.reshape(-1, 3))
    assert np.all((uv >= 10 - 0.5) & (uv <= np.array(setup.image_size) - 10.5))
    # the tilt, here from the camera centre in the board frame: it must be on the −z side
    for qi, t in zip(q, board_tilt(puma, q, setup), strict=True):
        T = puma.fk(qi)
        if setup.mode == "eye_in_hand":
            cam, board = T @ setup.camera, setup.target
        else:
            cam, board = setup.camera, T @ setup.target
        eye = np.linalg.solve(board, cam[:, 3])[:3] - setup.board.centre
        assert eye[2] < 0
        assert math.isclose(t, math.acos(-eye[2] / np.linalg.norm(eye)), abs_tol=1e-9)
        assert t <= tilt
    # and the draws it turned down: at least one of them does not see the board
    rng = np.random.default_rng(5)
    others = np.clip(PUMA_Q0 + 0.3 * rng.standard_normal((200, 6)), *puma.limits.T)
    assert not visible(puma, others, setup, tilt).all()


def test_views_that_cannot_see_the_board_are_refused(puma):
    setup = eye_in_hand_setup(puma)
    behind = CameraSetup(
        "eye_in_hand", setup.camera, setup.target @ np.diag([1.0, -1, -1, 1]), LENS
    )  # the board turned over: the camera would see its back
    assert not visible(puma, PUMA_Q0, behind)[0]
    with pytest.raises(cc.CalibrationError, match="only 0 of"):
        select_views(puma, 3, behind, seed=1, q_centre=PUMA_Q0, spread=0.01, max_draws=500)
    far = np.array(PUMA_Q0)
    far[0] += 2.0
    with pytest.raises(cc.CalibrationError, match=r"behind the camera|outside"):
        simulate_pixels(puma, far, setup)


def test_inverse_and_look_at():
    rng = np.random.default_rng(8)
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rng.normal(size=3))[0]
    T[:3, 3] = rng.normal(size=3)
    assert np.allclose(inverse(T) @ T, np.eye(4), atol=1e-14)
    C = look_at([1.0, 0, 0.5], [2.0, 0, 0.5])
    # looking along +x with z up: image right is −y, image down is −z
    assert np.allclose(C[:3, :3], [[0, 0, 1], [-1, 0, 0], [0, -1, 0]])
    with pytest.raises(cc.CalibrationError, match="rigid"):
        CameraSetup("eye_in_hand", 2 * np.eye(4), np.eye(4), LENS)
    with pytest.raises(cc.CalibrationError, match="mode"):
        CameraSetup("eye_on_hand", np.eye(4), np.eye(4), LENS)


# --- residuals and their Jacobian ---------------------------------------------------------


def cv2_residuals(robot, q, pixels, mode, camera, target, intr, board, sigma):
    """(uv − π)/σ with π from cv2.projectPoints of T_cam←target composed here."""
    K, dist = intr.to_opencv()
    out = []
    for qi, uvi in zip(np.atleast_2d(q), pixels, strict=True):
        T = robot.fk(qi)
        M = (
            np.linalg.inv(T @ camera) @ target
            if mode == "eye_in_hand"
            else np.linalg.inv(camera) @ T @ target
        )
        uv, _ = cv2.projectPoints(board.corners(), cv2.Rodrigues(M[:3, :3])[0], M[:3, 3], K, dist)
        out.append((uvi - uv.reshape(-1, 2)) / sigma)
    return np.ravel(out)


def moved(T, delta):
    """T moved by (δt, δw) in its parent frame: [exp([δw]×) R | t + δt], via OpenCV."""
    out = np.array(T, dtype=float)
    out[:3, :3] = cv2.Rodrigues(np.asarray(delta[3:], float))[0] @ out[:3, :3]
    out[:3, 3] += delta[:3]
    return out


@pytest.mark.parametrize("make", [eye_in_hand_setup, eye_to_hand_setup])
def test_residual_jacobian_matches_central_differences(puma, make):
    """Every column (37 robot parameters in deviations, 2 × 6 pose deviations, 9
    intrinsics) against central differences of residuals computed with OpenCV."""
    from casecal.observations.residuals import camera_residuals

    setup = make(puma)
    q = select_views(puma, 4, setup, seed=6, q_centre=PUMA_Q0, spread=0.15)
    uv = simulate_pixels(puma, q, setup, sigma_px=0.3, seed=7)
    sigma = 0.3
    r, J, names = camera_residuals(puma, q, uv, setup, sigma_px=sigma)
    assert J.shape == (4 * 63 * 2, 37 + 12 + 9) and len(names) == J.shape[1]
    args = (setup.mode, setup.camera, setup.target, setup.intrinsics, setup.board, sigma)
    assert np.abs(r - cv2_residuals(puma, q, uv, *args)).max() < 1e-8

    def at(name, h):
        robot, mode, camera, target, intr, board, s = puma, *args
        if name in puma.parameter_names:
            robot = puma.with_deviations({name: h})
        elif name.startswith(("camera_", "target_")):
            k = ["x", "y", "z", "wx", "wy", "wz"].index(name.partition("_")[2])
            delta = h * np.eye(6)[k]
            if name.startswith("camera_"):
                camera = moved(camera, delta)
            else:
                target = moved(target, delta)
        else:
            v = intr.vector() + h * np.eye(9)[INTRINSIC_NAMES.index(name)]
            intr = Intrinsics.from_vector(v)
        return cv2_residuals(robot, q, uv, mode, camera, target, intr, board, s)

    for k, name in enumerate(names):
        h = 1e-3 if name in ("fx", "fy", "cx", "cy") else 1e-6
        fd = (at(name, h) - at(name, -h)) / (2 * h)
        scale = max(1.0, np.abs(J[:, k]).max())
        assert np.abs(J[:, k] - fd).max() < 1e-6 * scale, name


def test_residuals_refuse_what_they_do_not_support(puma):
    from casecal.observations.residuals import camera_residuals

    setup = eye_in_hand_setup(puma)
    q = select_views(puma, 2, setup, seed=6, q_centre=PUMA_Q0, spread=0.15)
    uv = simulate_pixels(puma, q, setup)
    r, J, names = camera_residuals(puma, q, uv, setup, parameters=[], poses=False)
    assert np.abs(r).max() < 1e-9 and names == list(INTRINSIC_NAMES) and J.shape == (252, 9)
    bad = uv.copy()
    bad[0, 3, 0] = np.nan
    with pytest.raises(cc.CalibrationError, match="not finite"):
        camera_residuals(puma, q, bad, setup)
    with pytest.raises(cc.CalibrationError, match="shape"):
        camera_residuals(puma, q, uv[:, :-1], setup)
    with pytest.raises(cc.CalibrationError, match="sigma_px"):
        camera_residuals(puma, q, uv, setup, sigma_px=0)


@pytest.mark.parametrize("make", [eye_in_hand_setup, eye_to_hand_setup])
def test_gauss_newton_on_pixels_recovers_a_simulated_truth(puma, make):
    """The Jacobian drives a fit: from the nominal robot, camera, board and lens, Gauss–Newton
    on 40 noisy views (σ = 0.3 px) finds the truth within its own standard errors.

    Columns: the DH parameters, both poses and the intrinsics (the base and tool frames
    are the board's and camera's poses over again), minus those a pivoted QR finds
    dependent; the truth deviates in every kept column.
    """
    from scipy.linalg import qr

    from casecal.model.frames import rotation_vector
    from casecal.observations.residuals import camera_residuals, moved_setup

    start = make(puma)
    q = select_views(puma, 40, start, seed=1, q_centre=PUMA_Q0, spread=0.3, max_tilt=0.9)
    dh = [n for n in puma.parameter_names if not n.startswith(("base_", "tool_"))]
    _, J, names = camera_residuals(puma, q, simulate_pixels(puma, q, start), start, parameters=dh)
    _, R, order = qr(J / np.linalg.norm(J, axis=0), pivoting=True, mode="economic")
    rank = int(np.sum(np.abs(np.diag(R)) > 1e-8 * abs(R[0, 0])))
    kept = [names[i] for i in sorted(order[:rank])]
    assert rank == 39  # 30 of a 6R arm's full pose, 9 intrinsics
    kept_dh = [n for n in kept if n in dh]

    rng = np.random.default_rng(3)
    sizes = {"fx": 10.0, "fy": 10.0, "cx": 5.0, "cy": 5.0}  # px
    truth = {}
    for n in kept:
        if n in dh:
            truth[n] = rng.normal(0, 1e-3)  # m, rad
        elif n.startswith(("camera_", "target_")):
            truth[n] = rng.normal(0, 5e-3)
        else:
            truth[n] = rng.normal(0, sizes.get(n, 5e-3))
    true_robot = puma.with_deviations({n: truth[n] for n in kept_dh})
    true_setup = moved_setup(start, {n: v for n, v in truth.items() if n not in dh})
    sigma = 0.3
    uv = simulate_pixels(true_robot, q, true_setup, sigma_px=sigma, seed=4)

    robot, setup = puma, start
    for _ in range(15):
        r, J, names = camera_residuals(robot, q, uv, setup, sigma, parameters=kept_dh)
        step = -np.linalg.lstsq(J[:, [names.index(n) for n in kept]], r, rcond=None)[0]
        robot = robot.with_deviations({n: v for n, v in zip(kept, step, strict=True) if n in dh})
        setup = moved_setup(setup, {n: v for n, v in zip(kept, step, strict=True) if n not in dh})
        if np.abs(step).max() < 1e-9:
            break
    else:
        pytest.fail("Gauss–Newton did not converge in 15 steps")
    r, J, names = camera_residuals(robot, q, uv, setup, sigma, parameters=kept_dh)
    Jk = J[:, [names.index(n) for n in kept]]
    sd = np.sqrt(np.diag(np.linalg.inv(Jk.T @ Jk)))
    assert 0.9 < r @ r / (len(r) - len(kept)) < 1.1  # χ²/dof of 5000 residuals
    error = robot.deviations_from(true_robot, kept_dh)
    for prefix, est, tru in (
        ("camera_", setup.camera, true_setup.camera),
        ("target_", setup.target, true_setup.target),
    ):
        moves = np.r_[est[:3, 3] - tru[:3, 3], rotation_vector(est[:3, :3] @ tru[:3, :3].T)]
        axes = ("x", "y", "z", "wx", "wy", "wz")
        error |= {prefix + a: v for a, v in zip(axes, moves, strict=True)}
    lens = setup.intrinsics.vector() - true_setup.intrinsics.vector()
    error |= dict(zip(INTRINSIC_NAMES, lens, strict=True))
    z = np.array([error[n] / s for n, s in zip(kept, sd, strict=True)])
    assert np.abs(z).max() < 4.5, kept[int(np.argmax(np.abs(z)))]
    # and it moved: the truth was many standard errors away from the start
    assert np.abs([truth[n] for n in kept] / sd).max() > 20
