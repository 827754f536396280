"""GroupedRetrieval: the torchmetrics wrapper of zoo.eval.retrieval, against a hand-checked case."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from lit_models.retrieval_metric import GroupedRetrieval
from zoo.eval.retrieval import grouped_retrieval_metrics

# 7 clips in groups of 3 (the 7th is dropped). Ranks worked out by hand, ties pessimistic:
#   clip 0 (id 0): t0 = 1 ties t2 (id 2) = 1          -> rank 2 (a strict ">" would say 1)
#   clip 1 (id 1): t1 = 1 beats 0, 0                  -> rank 1
#   clip 2 (id 2): t2 = 1 ties t0 (id 0) = 1          -> rank 2
#   clip 3 (id 3): best correct t4 = 0.8 < t5 = 1     -> rank 2 (t3, also id 3, scores 0)
#   clip 4 (id 3): t3 = 1 beats 0.6, 0                -> rank 1
#   clip 5 (id 4): t5 = 0.6 < t3 = 0.8, t4 = 0.96     -> rank 3
VIDEO = torch.tensor(
    [[1.0, 0.0], [0.0, 1.0], [1.0, 0.0], [0.0, 1.0], [1.0, 0.0], [0.8, 0.6], [1.0, 0.0]]
)
TEXT = torch.tensor(
    [[1.0, 0.0], [0.0, 1.0], [1.0, 0.0], [1.0, 0.0], [0.6, 0.8], [0.0, 1.0], [0.0, 1.0]]
)
IDS = torch.tensor([0, 1, 2, 3, 3, 4, 5])
EXPECTED = {"R@1": 2 / 6, "R@2": 5 / 6, "R@3": 1.0, "MeanR": 11 / 6, "queries": 6.0}


def update_in_batches(metric: GroupedRetrieval, rows: slice = slice(None)) -> None:
    """Batches of 2, 3 and 2 clips, so that groups straddle update() calls."""
    video, text, ids = VIDEO[rows], TEXT[rows], IDS[rows]
    for batch in (slice(0, 2), slice(2, 5), slice(5, None)):
        metric.update(video[batch], text[batch], ids[batch])


def test_updates_equal_grouped_metrics_on_the_concatenation_with_pessimistic_ties():
    metric = GroupedRetrieval(group_size=3, top_ks=(1, 2, 3), prefix="val/")
    update_in_batches(metric)
    computed = metric.compute()
    assert computed == pytest.approx({f"val/{key}": value for key, value in EXPECTED.items()})
    whole = grouped_retrieval_metrics(VIDEO, TEXT, IDS, group_size=3, top_ks=(1, 2, 3))
    assert computed == {f"val/{key}": value for key, value in whole.items()}


def test_reset_clears_the_clips_of_the_last_epoch():
    metric = GroupedRetrieval(group_size=3, top_ks=(1, 2, 3))
    other = torch.tensor([[0.0, 1.0]] * 7)
    metric.update(other, other, torch.arange(7))  # all equal: every clip ranks last
    assert metric.compute()["MeanR"] == 3.0
    metric.reset()
    assert metric.update_count == 0
    assert metric.video == metric.text == metric.caption_id == []
    update_in_batches(metric)
    assert metric.compute() == pytest.approx(EXPECTED)


def test_fewer_clips_than_a_group_warn_and_return_nothing():
    metric = GroupedRetrieval(group_size=64, prefix="test/")
    update_in_batches(metric)
    with pytest.warns(UserWarning, match="test/retrieval: 7 held-out clips are fewer than"):
        assert metric.compute() == {}


def test_states_stay_out_of_checkpoints():
    metric = GroupedRetrieval(group_size=3)
    update_in_batches(metric)
    assert metric.state_dict() == {}


DDP_SCRIPT = """
import json, os, socket, sys
import torch.distributed as dist
import torch.multiprocessing as mp
sys.path.insert(0, sys.argv[1])
from test_retrieval_metric import GroupedRetrieval, update_in_batches

def worker(rank, port, results):
    os.environ.update(MASTER_ADDR="127.0.0.1", MASTER_PORT=str(port))
    dist.init_process_group("gloo", rank=rank, world_size=2)
    try:
        metric = GroupedRetrieval(group_size=3, top_ks=(1, 2, 3))
        # Rank 0 holds clips 0-3, rank 1 clips 4-6: groups straddle ranks.
        update_in_batches(metric, slice(0, 4) if rank == 0 else slice(4, None))
        results[rank] = metric.compute()
        results[f"local{rank}"] = sum(len(ids) for ids in metric.caption_id)  # unsynced again
    finally:
        dist.destroy_process_group()

if __name__ == "__main__":
    with mp.Manager() as manager:
        results = manager.dict()
        with socket.socket() as free:  # a port nobody uses, for the two ranks to meet on
            free.bind(("127.0.0.1", 0))
            port = free.getsockname()[1]
        mp.start_processes(worker, args=(port, results), nprocs=2, start_method="fork")
        print(json.dumps({str(k): v for k, v in dict(results).items()}))
"""


def test_ddp_sync_gathers_every_rank_in_rank_order(tmp_path):
    # Two gloo ranks forked from a fresh interpreter: forking this one, where JAX may already
    # run threads, can deadlock the children.
    script = tmp_path / "ddp_sync.py"
    script.write_text(DDP_SCRIPT)
    run = subprocess.run([sys.executable, str(script), str(Path(__file__).parent)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    results = {k: v for k, v in json.loads(run.stdout.strip().splitlines()[-1]).items()}
    results = {int(k) if k.isdigit() else k: v for k, v in results.items()}
    assert results[0] == results[1] == pytest.approx(EXPECTED)
    assert results["local0"] == 4 and results["local1"] == 3  # each rank keeps its own clips
