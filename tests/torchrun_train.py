"""One process of the torchrun test (tests/test_torchrun.py): ``python -m torch.distributed.run
--nproc_per_node=N tests/torchrun_train.py OUT STEPS [BATCH]`` trains test_train_loop's tiny
configuration on its fake still frames; rank, world size and the process group come from torchrun's
environment (airpose_lib.train.run.train), nothing else tells this script it is distributed."""
import sys

from test_train_loop import FAKES, tiny_config  # this file's folder is sys.path[0]

from airpose_lib.train import train


def config(steps: int, batch_size: int):
    """The configuration the test compares across launches (dropout off: per-process masks)."""
    return tiny_config(steps=steps, batch_size=batch_size, val_every=None, checkpoint_every=2,
                       data={"n": 9, "genders": 1}, model={"num_iterations": 2, "dropout": 0.0},
                       device="cpu")  # gloo processes, also on a machine with fewer GPUs than processes


if __name__ == "__main__":
    out, steps = sys.argv[1], int(sys.argv[2])
    batch = int(sys.argv[3]) if len(sys.argv) > 3 else 3
    result = train("airpose", config=config(steps, batch), out_dir=out, **FAKES)
    print(f"rank done: step {result.step} world {result.config['world_size']}")
