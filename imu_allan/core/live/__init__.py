"""
The live estimator: what the allan node runs (``analyze --online`` runs the same).

* :mod:`.online`: the pipeline (stamp checks, stationarity gate, streaming Allan variance, the
  sensor's processing, fit) and the staged publish cycle;
* :mod:`.streaming`: the bounded-memory overlapping Allan (and modified, Hadamard) variance;
* :mod:`.stationarity`: the gate that leaves moving spans out;
* :mod:`.health`: the node's diagnostic records (stream, noise budget);
* :mod:`.change_monitor`: the live change test over the published estimates.
"""
