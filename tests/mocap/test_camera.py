"""The camera conventions (tbha_graph/mocap/camera.py): world y up, camera x right / y down / z forward,
pixels from the top-left corner."""
from __future__ import annotations

import numpy as np

from tbha_graph.mocap import skeleton as sk
from tbha_graph.mocap.camera import Camera


def front_camera() -> Camera:
    # 4 m in front of an actor who faces +z, at chest height, looking back at them
    return Camera.look_at((0.0, 1.2, 4.0), (0.0, 1.0, 0.0), focal_px=600.0, width=640, height=480)


def test_axes_and_pixels():
    cam = front_camera()
    assert np.isclose(np.linalg.det(cam.R), 1.0) and np.allclose(cam.R @ cam.R.T, np.eye(3))
    pose = sk.tpose()
    px = cam.project(pose)
    assert cam.in_image(px).all()  # in front of the camera, inside the image
    assert (cam.to_camera(pose)[:, 2] > 0).all()  # z forward
    head, hips = px[sk.JOINT_INDEX["head"]], px[sk.JOINT_INDEX["hips"]]
    assert head[1] < hips[1]  # world up is image up (pixel v grows downwards)
    # facing the actor, their left hand (+x world) appears on the image's right
    assert px[sk.JOINT_INDEX["left_wrist"]][0] > px[sk.JOINT_INDEX["right_wrist"]][0]
    # the target projects at the principal point ((w-1)/2, (h-1)/2): pixel centres are integers from the top-left
    assert np.allclose(cam.project(np.array([0.0, 1.0, 0.0])), [319.5, 239.5])


def test_round_trips_and_rays():
    cam = front_camera()
    pts = np.random.default_rng(0).uniform(-1, 1, (5, 7, 3)) + [0, 1, 0]
    assert np.allclose(cam.to_world(cam.to_camera(pts)), pts)
    px = cam.project(pts)
    rays = cam.rays(px)
    pc = cam.to_camera(pts)
    assert np.allclose(rays, pc / np.linalg.norm(pc, axis=-1, keepdims=True))
    assert np.allclose(cam.center, [0.0, 1.2, 4.0])
    assert Camera.from_dict(cam.to_dict()).to_dict() == cam.to_dict()


def test_distortion_moves_points_radially():
    cam = front_camera()
    bent = Camera(cam.K, cam.R, cam.t, cam.width, cam.height, dist=[-0.2, 0, 0, 0, 0])
    p = np.array([0.8, 1.9, 0.0])  # off-centre
    c = np.array([319.5, 239.5])
    assert np.linalg.norm(bent.project(p) - c) < np.linalg.norm(cam.project(p) - c)  # barrel: pulled inwards
