"""A Doppler estimator written in Python, swapped in for the built-in `doppler` node:

    [nodes.doppler.variants.python]
    exec = "python3"
    args = ["../nodes/python/examples/lag1_estimator.py"]   # relative to the launch file
    ports = { iq = "IqFrameV3", vector = "VectorFieldV2", maps = "DopplerMapV2" }

    sonoflow run launch/quickstart.toml --swap doppler=python

Per packet and (transmit, receive) angle pair it calls sonoflow's lag-L slow-time
autocorrelation (`sonoflow.doppler_maps`, the built-in estimator's code, paper 1 eq. 19), then
solves the least-squares (vx, vz) over the looks in numpy and publishes one Doppler map per look
and the vector field (planes vx, vz, flags, power), as the built-in node does. The projection a
(the velocity a look measures is a · (vx, vz)) is, as in the built-in node, per pixel through the
receive aperture the I/Q header carries (`sonoflow.look_projection`, `projection = "aperture"`,
the default) or the nominal plane wave a = −(sin θt + sin θr, cos θt + cos θr)/2
(`projection = "nominal"`, also where a header carries no aperture). Params: `lag` (1 … 16),
`projection`.
"""

import time

import numpy as np

import sonoflow as sf

C = sf.node.CONSTANTS
NO_ESTIMATE = 1


_PROJECTIONS = {}


def look_projection(h, projection, n):
    """The look's projection (a_x, a_z) per pixel, float64: through its aperture (cached per look
    geometry, as the built-in node does) or the nominal plane wave."""
    convex = h["n_elements"] > 0 and np.isfinite(h["radius"]) and h["radius"] > 0
    if projection == "nominal" and convex:
        # as the built-in node: the angles of a convex array's looks are taken from each
        # element's normal, which no plane-wave projection describes
        raise RuntimeError("lag1_estimator: projection = \"nominal\" on a convex array: use \"aperture\"")
    if projection == "aperture":
        g = h["grid"]
        key = tuple(float(h[k]) for k in ("tx_angle", "rx_angle", "fc", "c", "pitch", "n_elements", "fnumber",
                                          "element_width", "radius", "apodization"))
        key += tuple(float(g[k]) for k in ("x0", "z0", "dx", "dz", "nx", "nz"))
        if key not in _PROJECTIONS:
            _PROJECTIONS[key] = sf.look_projection(h)
        a = _PROJECTIONS[key]
        if a is not None:
            return a[0].reshape(-1).astype(np.float64), a[1].reshape(-1).astype(np.float64)
    return (np.full(n, -(np.sin(h["tx_angle"]) + np.sin(h["rx_angle"])) / 2),
            np.full(n, -(np.cos(h["tx_angle"]) + np.cos(h["rx_angle"])) / 2))


def estimate(node, looks, lag, projection):
    t0 = time.thread_time_ns()
    first = next(iter(looks.values()))["header"]
    g = first["grid"]
    nz, nx = g["nz"], g["nx"]
    n = nz * nx
    if len(looks) < 2:
        raise RuntimeError(f"packet {first['packet']}: vector Doppler needs two angle pairs, got {len(looks)}")
    ata = np.zeros((3, n))
    atb = np.zeros((2, n))
    used = np.zeros(n, dtype=np.int64)
    power = np.zeros(n, dtype=np.float32)
    frame_id = 0
    for look in looks.values():
        h = look["header"]
        packet = np.stack([f.reshape(nz, nx) for f in look["frames"]], axis=2)
        v, _var, p, flags = sf.doppler_maps(packet, {"fc": h["fc"], "c": h["c"], "PRF": h["prf"]}, 1, lag)
        a0, a1 = look_projection(h, projection, n)
        ok = (flags.reshape(-1) & NO_ESTIMATE) == 0
        vd = v.reshape(-1).astype(np.float64)
        b0, b1 = a0[ok], a1[ok]
        ata[0, ok] += b0 * b0
        ata[1, ok] += b0 * b1
        ata[2, ok] += b1 * b1
        atb[0, ok] += b0 * vd[ok]
        atb[1, ok] += b1 * vd[ok]
        used += ok
        power += p.reshape(-1) / len(looks)
        frame_id = max(frame_id, h["common"]["frame_id"])
        if "maps" in node.outputs:
            mh = {
                "common": {"frame_id": h["common"]["frame_id"], "t_valid": h["common"]["t_valid"]},
                "grid": g, "fc": h["fc"], "c": h["c"], "prf": h["prf"], "rx_angle": h["rx_angle"],
                "tx_angle": h["tx_angle"], "nyquist_velocity": h["c"] * h["prf"] / (4 * h["fc"] * lag),
                "packet": h["packet"], "packet_size": len(look["frames"]), "n_planes": 5, "estimator": 101,
                "plane_ids": [C["PLANE_VELOCITY"], C["PLANE_POWER"], C["PLANE_FLAGS"], C["PLANE_PROJECTION_X"],
                              C["PLANE_PROJECTION_Z"]],
            }
            planes = np.stack([v.reshape(-1), p.reshape(-1), (~ok).astype(np.float32), a0.astype(np.float32),
                               a1.astype(np.float32)])
            node.publish("maps", mh, planes)
    a11, a12, a22 = ata
    det = a11 * a22 - a12 * a12
    good = (used >= 2) & (det > 1e-6 * (a11 + a22) ** 2)
    out = np.zeros((4, n), dtype=np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        out[0] = np.where(good, (a22 * atb[0] - a12 * atb[1]) / det, 0.0)
        out[1] = np.where(good, (a11 * atb[1] - a12 * atb[0]) / det, 0.0)
    out[2] = np.where(good, 0.0, 1.0)
    out[3] = power
    vh = {
        "common": {"frame_id": frame_id, "t_valid": first["common"]["t_valid"],
                   "compute_ns": time.thread_time_ns() - t0},
        "grid": g, "n_planes": 4, "source": C["VECTOR_RAW"], "packet": first["packet"], "converged": 1,
        "n_looks": len(looks),
        "plane_ids": [C["PLANE_VX"], C["PLANE_VZ"], C["PLANE_FLAGS"], C["PLANE_POWER"]],
    }
    node.publish("vector", vh, out)


def main():
    with sf.Node() as node:
        lag = node.params.get("lag", 1)
        if not (isinstance(lag, int) and 1 <= lag <= 16):
            raise SystemExit(f"lag1_estimator: params.lag = {lag!r} is out of range: 1 ..= 16")
        projection = node.params.get("projection", "aperture")
        if projection not in ("aperture", "nominal"):
            raise SystemExit(f"lag1_estimator: params.projection = {projection!r}: \"aperture\" or \"nominal\"")
        looks, packet = {}, None
        for m in node.messages("iq"):
            h = m.header
            if packet is not None and h["packet"] != packet:
                estimate(node, looks, lag, projection)
                looks = {}
            packet = h["packet"]
            key = (h["tx_angle"], h["rx_angle"])
            looks.setdefault(key, {"header": h, "frames": []})["frames"].append(m.data)
        if looks:
            estimate(node, looks, lag, projection)


if __name__ == "__main__":
    main()
