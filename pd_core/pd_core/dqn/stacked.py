"""Several paper Q-networks (Table 2: tanh MLP, RMSProp, Eq. 11's MSE loss) as one set of tensors.

`StackedQ` holds A agents' online networks and their target networks in one float32 matrix of
shape (2A, P): row a < A is agent a's online network, row A + a its target network, each row all
of one network's parameters. Layer l's weight and bias are stored together as one augmented
matrix [W^T; b] of shape (n_in + 1, n_out), so that a layer is one batched matrix product of the
activations with a column of ones appended (`x_aug @ [W^T; b] = x W^T + b`). That layout makes
the whole DQN update a few dozen kernels, whatever A is:

- one forward pass computes the online networks on the states and the target networks on the
  next states (4 `bmm` + 3 `tanh`, over 2A matrices);
- the backward pass is written out (a `bmm` per weight gradient, one per layer input, one
  `tanh_backward`), with each gradient written in place into one (A, P) matrix;
- RMSProp (torch's formula, `alpha` 0.99, `eps` 1e-8, no momentum) is five kernels over it;
- the target copy every n_T updates is one `where` on a flag held on the device.

No autograd, no optimiser object and no host read-back: a CUDA graph can hold any number of
updates. On the CPU the same code runs eagerly. `from_networks` / `network` convert to and from
`pd_core.dqn.network.QNetwork`, so the files saved are the usual policy files.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from pd_core.dqn.network import QNetwork

RMSPROP_ALPHA = 0.99
"""torch.optim.RMSprop's default smoothing constant (the reference loop's optimiser)"""
RMSPROP_EPS = 1e-8
"""torch.optim.RMSprop's default epsilon"""


@dataclass(frozen=True)
class Layer:
    """Where one layer's augmented matrix [W^T; b] lives in a row of the parameter matrix."""

    n_in: int
    n_out: int
    offset: int

    @property
    def size(self) -> int:
        return (self.n_in + 1) * self.n_out

    @property
    def cols(self) -> slice:
        return slice(self.offset, self.offset + self.size)


def layers_of(widths: tuple[int, ...]) -> tuple[Layer, ...]:
    out, offset = [], 0
    for n_in, n_out in zip(widths[:-1], widths[1:], strict=True):
        out.append(Layer(n_in, n_out, offset))
        offset += (n_in + 1) * n_out
    return tuple(out)


class Buffers:
    """The activations of one forward pass (ones columns set once, never written again)."""

    def __init__(self, rows: int, batch: int, widths: tuple[int, ...], dev: torch.device) -> None:
        self.h = [torch.ones((rows, batch, w + 1), device=dev) for w in widths[1:-1]]
        self.z = [torch.empty((rows, batch, w), device=dev) for w in widths[1:-1]]
        self.q = torch.empty((rows, batch, widths[-1]), device=dev)


class StackedQ:
    """A agents' online and target Q-networks, their RMSProp state and their gradients.

    `params` (2A, P): online rows then target rows; `grads` and `square_avg` (A, P). Every
    method writes into these tensors in place (a captured graph keeps reading them).
    """

    def __init__(
        self,
        widths: tuple[int, ...],
        n_agents: int,
        lr: float,
        device: torch.device | str = "cpu",
    ) -> None:
        if n_agents < 1:
            raise ValueError(f"n_agents must be >= 1, got {n_agents}")
        self.widths, self.n_agents, self.lr = tuple(widths), n_agents, float(lr)
        self.device = torch.device(device)
        self.layers = layers_of(self.widths)
        self.size = sum(layer.size for layer in self.layers)
        a, dev = n_agents, self.device
        self.params = torch.zeros((2 * a, self.size), device=dev)
        self.grads = torch.zeros((a, self.size), device=dev)
        self.square_avg = torch.zeros((a, self.size), device=dev)
        self._avg = torch.zeros((a, self.size), device=dev)
        self.weights = [self._view(self.params, layer) for layer in self.layers]
        self.grad_views = [self._view(self.grads, layer) for layer in self.layers]

    @staticmethod
    def _view(m: torch.Tensor, layer: Layer) -> torch.Tensor:
        return m[:, layer.cols].view(m.shape[0], layer.n_in + 1, layer.n_out)

    # ---- conversion
    @classmethod
    def from_networks(
        cls, nets: list[QNetwork], lr: float, device: torch.device | str = "cpu"
    ) -> StackedQ:
        """Online and target networks of every agent start at `nets[a]`'s weights (as a
        `DQNAgent` starts its target network as a copy of its online one)."""
        widths = (nets[0].n_inputs, *nets[0].hidden, nets[0].n_actions)
        for net in nets:
            if net.near_pad or net.activation != "tanh":
                raise ValueError("StackedQ holds the paper's network: tanh, no near-pad inputs")
            if (net.n_inputs, *net.hidden, net.n_actions) != widths:
                raise ValueError("every stacked network must have the same widths")
        out = cls(widths, len(nets), lr, device)
        with torch.no_grad():
            for a, net in enumerate(nets):
                out.load_network(a, net)
        return out

    def load_network(self, agent: int, net: QNetwork) -> None:
        """Agent `agent`'s online and target networks <- `net`'s weights."""
        linears = [m for m in net.net if isinstance(m, torch.nn.Linear)]
        with torch.no_grad():
            for layer, lin in zip(self.layers, linears, strict=True):
                aug = torch.cat([lin.weight.detach().t(), lin.bias.detach()[None]]).to(self.device)
                for row in (agent, self.n_agents + agent):
                    self.params[row, layer.cols].copy_(aug.reshape(-1))

    def network(self, agent: int, target: bool = False) -> QNetwork:
        """A CPU `QNetwork` holding agent `agent`'s online (or target) weights."""
        row = self.n_agents + agent if target else agent
        net = QNetwork(self.widths[0], self.widths[-1], self.widths[1:-1])
        linears = [m for m in net.net if isinstance(m, torch.nn.Linear)]
        with torch.no_grad():
            for layer, lin in zip(self.layers, linears, strict=True):
                aug = self.params[row, layer.cols].view(layer.n_in + 1, layer.n_out).cpu()
                lin.weight.copy_(aug[:-1].t())
                lin.bias.copy_(aug[-1])
        return net

    def buffers(self, rows: int, batch: int) -> Buffers:
        return Buffers(rows, batch, self.widths, self.device)

    def inputs(self, rows: int, batch: int, lead: tuple[int, ...] = ()) -> torch.Tensor:
        """An input buffer (*lead, rows, batch, n_in + 1) with its ones column set."""
        return torch.ones((*lead, rows, batch, self.widths[0] + 1), device=self.device)

    # ---- the update
    def forward(self, x: torch.Tensor, buf: Buffers) -> torch.Tensor:
        """Q-values (rows, B, n_actions) of the networks 0..rows-1 (online rows first) on `x`
        (rows, B, n_in + 1; last column ones); the activations stay in `buf` for `backward`."""
        rows = x.shape[0]
        h = x
        last = len(self.layers) - 1
        for i, w in enumerate(self.weights):
            if i == last:
                torch.bmm(h, w[:rows], out=buf.q[:rows])
                break
            torch.bmm(h, w[:rows], out=buf.z[i][:rows])
            torch.tanh(buf.z[i][:rows], out=buf.h[i][:rows, :, :-1])
            h = buf.h[i][:rows]
        return buf.q[:rows]

    def backward(self, x: torch.Tensor, buf: Buffers, dq: torch.Tensor) -> None:
        """`grads` <- the gradient of the online networks' loss whose gradient with respect to
        their outputs is `dq` (A, B, n_actions), after `forward(x, buf)` over (at least) the
        online rows."""
        a = self.n_agents
        ins = [x[:a], *(h[:a] for h in buf.h)]
        d = dq
        for i in range(len(self.layers) - 1, -1, -1):
            torch.bmm(ins[i].transpose(1, 2), d, out=self.grad_views[i])
            if i == 0:
                break
            w_no_bias = self.weights[i][:a, :-1, :]
            dh = torch.bmm(d, w_no_bias.transpose(1, 2))
            d = torch.ops.aten.tanh_backward(dh, buf.h[i - 1][:a, :, :-1])

    def rmsprop_step(self) -> None:
        """torch.optim.RMSprop's step (no momentum, not centred) on every online network."""
        sq = self.square_avg
        sq.mul_(RMSPROP_ALPHA).addcmul_(self.grads, self.grads, value=1.0 - RMSPROP_ALPHA)
        torch.sqrt(sq, out=self._avg).add_(RMSPROP_EPS)
        self.params[: self.n_agents].addcdiv_(self.grads, self._avg, value=-self.lr)

    def copy_target_where(self, flag: torch.Tensor) -> None:
        """Target networks <- online networks where the 0-d bool `flag` is set (a device
        tensor: the copy every n_T updates inside a captured graph), exactly."""
        a = self.n_agents
        torch.where(flag, self.params[:a], self.params[a:], out=self.params[a:])

    def sync_target(self) -> None:
        self.params[self.n_agents :].copy_(self.params[: self.n_agents])


def td_output_grad(
    q: torch.Tensor,
    actions: torch.Tensor,
    rewards: torch.Tensor,
    discounts: torch.Tensor,
    scale: torch.Tensor,
    dq: torch.Tensor,
) -> torch.Tensor:
    """Eq. 11's TD error and the gradient of its mean square with respect to the outputs.

    `q` (2A, B, n): online outputs on the states, then target outputs on the next states;
    `actions` (A, B) int64, `rewards` and `discounts` (A, B); `scale` (A, 1): 2 / B for an agent
    that learns, 0 for one that is done. Writes d loss / d Q into `dq` (A, B, n); returns the TD
    errors Q(s, a) - (r + discount * max_a' Q_T(s', a')) (A, B)."""
    a = actions.shape[0]
    q_sa = q[:a].gather(2, actions[..., None]).squeeze(2)
    target = torch.addcmul(rewards, discounts, q[a:].amax(2))
    diff = q_sa - target
    dq.zero_()
    dq.scatter_(2, actions[..., None], (diff * scale)[..., None])
    return diff
