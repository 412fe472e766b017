"""``markerplan reduce``: how few of a layout's markers still meet the requirement.

- :mod:`planner.reduction.curve`: the trade-off curve (fewest markers per worst error);
- :mod:`planner.reduction.minimax`: the integer program answering one curve query;
- :mod:`planner.reduction.losses`: drop order, per-marker losses and the shared layout checks;
- :mod:`planner.reduction.study`: the layout, its integer-program input and one study run;
- :mod:`planner.reduction.report`: the files and the summary;
- :mod:`planner.reduction.plot`: ``tradeoff.png``;
- :mod:`planner.reduction.verify`: ``--verify`` (simulate and process chosen curve points).
"""
