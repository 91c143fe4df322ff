"""Torch networks of paper §II: LSTM and CNN-LSTM regressors with a linear output.

Input: a sequence (batch, time, channels). Optional CNN front end (paper: two 1-D
convolutions, 16 filters, kernel 4, ReLU, then max-pooling 2), then a stacked LSTM
(paper: 3 layers x 150 units, dropout 0.5), then dropout, a 50-unit ReLU dense layer
and a LINEAR scalar output (the paper's softmax output cannot regress a scalar).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from opfbench.errors import InputError


@dataclass(frozen=True)
class NetConfig:
    """Architecture. `conv=False` gives the plain LSTM, `conv=True` the CNN-LSTM."""

    conv: bool
    hidden: int = 150
    layers: int = 3
    dropout: float = 0.5
    filters: int = 16
    kernel: int = 4
    pool: int = 2
    dense: int = 50

    def sequence_length(self, window: int) -> int:
        """Length of the sequence the LSTM sees for an input window of `window` steps."""
        if not self.conv:
            return window
        return (window - 2 * (self.kernel - 1)) // self.pool


class SequenceRegressor(nn.Module):
    """[conv front end] -> stacked LSTM -> dropout -> dense ReLU -> linear scalar."""

    def __init__(self, channels: int, window: int, config: NetConfig) -> None:
        super().__init__()
        if config.sequence_length(window) < 1:
            raise InputError(f"window {window} is too short for the network ({config})")
        self.front: nn.Module = (
            nn.Sequential(
                nn.Conv1d(channels, config.filters, config.kernel),
                nn.ReLU(),
                nn.Conv1d(config.filters, config.filters, config.kernel),
                nn.ReLU(),
                nn.MaxPool1d(config.pool),
            )
            if config.conv
            else nn.Identity()
        )
        self.lstm = nn.LSTM(
            input_size=config.filters if config.conv else channels,
            hidden_size=config.hidden,
            num_layers=config.layers,
            dropout=config.dropout if config.layers > 1 else 0.0,
            batch_first=True,
        )
        self.head = nn.Sequential(
            nn.Dropout(config.dropout),
            nn.Linear(config.hidden, config.dense),
            nn.ReLU(),
            nn.Linear(config.dense, 1),
        )

    def forward(self, sequence: torch.Tensor) -> torch.Tensor:
        """(batch, time, channels) -> (batch,)"""
        features = self.front(sequence.transpose(1, 2)).transpose(1, 2)
        output, _ = self.lstm(features)
        return self.head(output[:, -1, :]).squeeze(-1)
