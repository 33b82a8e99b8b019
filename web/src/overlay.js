// The overlay: tiles held / total, bytes received, converged or not, server updates; exposure and
// tone-map controls; a control-token field (kept in memory only, never in the URL) and buttons
// that move a node (an object or a light) with SceneEdit.
export class Overlay {
  constructor(params, onChange, onMove) {
    this.el = document.createElement('div');
    this.el.id = 'overlay';
    this.el.innerHTML = `
      <div id="o-status">connecting</div>
      <div id="o-tiles"></div><div id="o-bytes"></div><div id="o-server"></div>
      <div id="o-error" class="err"></div>
      <label>exposure (auto or stops) <input id="o-ev" type="text" size="5"></label>
      <label>tone map <select id="o-op"><option>reinhard</option><option>aces</option><option>clamp</option></select></label>
      <div>drag: orbit, right drag: pan, wheel: dolly, F: fly (WASD QE, arrows)</div>
      <details><summary>edit (control token)</summary><form id="o-form" onsubmit="return false">
        <label>token <input id="o-token" type="password" autocomplete="off">
        <input type="text" autocomplete="username" hidden></label>
        <label>node <select id="o-node"></select></label>
        <label>step <input id="o-step" type="number" value="0.1" step="0.05"></label>
        <div id="o-move"></div>
      </form></details>`;
    document.body.appendChild(this.el);
    this.$ = (id) => this.el.querySelector(`#o-${id}`);
    this.$('ev').value = params.exposure;
    this.$('op').value = params.tonemap;
    this.$('ev').addEventListener('change', () => {
      const v = this.$('ev').value.trim();
      if (v === 'auto' || (v !== '' && Number.isFinite(Number(v)))) onChange({ exposure: v });
    });
    this.$('op').addEventListener('change', () => onChange({ tonemap: this.$('op').value }));
    for (const [label, v] of [['-x', [-1, 0, 0]], ['+x', [1, 0, 0]], ['-y', [0, -1, 0]], ['+y', [0, 1, 0]],
      ['-z', [0, 0, -1]], ['+z', [0, 0, 1]]]) {
      const b = document.createElement('button');
      b.textContent = label;
      b.addEventListener('click', () => {
        const s = Number(this.$('step').value) || 0;
        onMove(this.$('token').value, this.$('node').value, { x: v[0] * s, y: v[1] * s, z: v[2] * s });
      });
      this.$('move').appendChild(b);
    }
    if (!params.ui) this.el.style.display = 'none';
  }

  setNodes(names) {
    const sel = this.$('node');
    sel.innerHTML = '';
    for (const n of names) {
      const o = document.createElement('option');
      o.value = n.target;
      o.textContent = n.label;
      sel.appendChild(o);
    }
  }

  update(s) {
    this.$('status').textContent = `${s.status}${s.converged ? ' · converged' : ''}`;
    this.$('tiles').textContent = `tiles ${s.held} / ${s.total}`;
    this.$('bytes').textContent = `received ${(s.bytes / 1048576).toFixed(2)} MiB, ${s.tilesApplied} tile updates, ${s.edits} edits`;
    this.$('server').textContent = s.stats
      ? `server: ${s.stats.updates} updates, convergence ${(+s.stats.convergence).toFixed(4)}${s.stats.engine_idle ? ', idle' : ''}`
      : '';
  }

  error(text) {
    this.$('error').textContent = text;
  }
}
