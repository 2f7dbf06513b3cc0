"""bench/cost.py's model: each process's CPU over the windows becomes ms per second per robot, and a host's robots."""

from bench.cost import HOST_CORES, model


def test_model_splits_each_cost_by_what_pays_for_it():
    base = {
        "sim": 0.2,
        "links": 0.1,
        "scheduler": 0.05,
        "web": 0.01,
        "executor": 0.0,
        "worker": 0.0,
        "control": 0.0,
        "redis": 0.01,
    }
    clients = {**base, "web": 0.21}  # 10 clients of 100 robots: 0.2 cores more
    driven = {**base, "executor": 0.2, "sim": 0.25, "redis": 0.02}  # 10 driven robots
    cfg = {"clients": 10, "driven": 10}
    got = model({"base": base, "clients": clients, "driven": driven}, cfg, 100)
    ms = got["ms_per_s"]
    assert (ms["sim_per_robot"], ms["links_per_robot"], ms["web_per_client_per_robot"]) == (2.0, 1.0, 0.2)
    assert (ms["executor_per_driven_robot"], ms["sim_per_driven_robot"], ms["redis_per_driven_robot"]) == (
        20.0,
        5.0,
        1.0,
    )
    # per robot with no client: 2 + 1 + 0.5 + 0.1 + 0.1 always, and a tenth of (20 + 5 + 1) for the driven
    assert got[f"robots_on_{HOST_CORES}_cores_by_clients"]["0"] == int(HOST_CORES / (6.3 / 1000))
    assert got[f"robots_on_{HOST_CORES}_cores_by_clients"]["50"] == int(HOST_CORES / (16.3 / 1000))
