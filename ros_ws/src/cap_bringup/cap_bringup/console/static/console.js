// The console page: renders the state the server sends over the websocket, sends what the person asks for.
// Everything shown comes from the graph or from users (commands, code, what the robot says): it is set as text
// (textContent), never as markup, so no text can become part of the page.
'use strict';

const $ = (id) => document.getElementById(id);
let socket = null;
const hiddenByDefault = (topic) => topic.endsWith('/depth');
const shown = new Map();  // topic -> whether its stream is on

function element(tag, text, className) {
  const node = document.createElement(tag);
  if (text !== undefined && text !== null) node.textContent = String(text);
  if (className) node.className = className;
  return node;
}

function send(request) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(request));
}

// The server's secret of this page: a camera stream is served only to an address that carries it, which a page of
// another site cannot read.
const pageToken = document.querySelector('meta[name="cap-page-token"]').content;

function streamUrl(topic) {
  return '/stream' + topic.split('/').map(encodeURIComponent).join('/') + '?token=' + encodeURIComponent(pageToken);
}

function renderCameras(streams) {
  const area = $('cameras');
  $('no-cameras').hidden = streams.length > 0;
  for (const figure of Array.from(area.querySelectorAll('figure'))) {
    if (!streams.includes(figure.dataset.topic)) figure.remove();
  }
  for (const topic of streams) {
    if (area.querySelector(`figure[data-topic="${CSS.escape(topic)}"]`)) continue;
    const figure = element('figure');
    figure.dataset.topic = topic;
    const image = element('img');
    image.alt = topic;
    image.dataset.topic = topic;
    const caption = element('figcaption');
    caption.append(element('span', topic));
    const toggle = element('label');
    const box = element('input');
    box.type = 'checkbox';
    if (!shown.has(topic)) shown.set(topic, !hiddenByDefault(topic));
    box.checked = shown.get(topic);
    // An unchecked stream is not fetched, so the console stops subscribing to it.
    const apply = () => { shown.set(topic, box.checked); if (box.checked) image.src = streamUrl(topic); else image.removeAttribute('src'); image.hidden = !box.checked; };
    box.addEventListener('change', apply);
    toggle.append(box, ' show');
    caption.append(toggle);
    figure.append(image, caption);
    area.append(figure);
    apply();
  }
}

function renderPlan(list, plan) {
  list.replaceChildren(...plan.map((step) => element('li', step.description)));
  if (plan.length === 0) list.append(element('li', 'no robot action'));
}

function renderTwin(command) {
  // The twin's picture after the rehearsal, beside the live cameras: fetched again only when it changed.
  const figure = $('twin');
  figure.hidden = !command || !command.twin;
  if (figure.hidden) return;
  const source = '/twin/' + encodeURIComponent(command.id) + '?v=' + command.twin + '&token=' +
    encodeURIComponent(pageToken);
  if ($('twin-image').getAttribute('src') !== source) $('twin-image').setAttribute('src', source);
}

function renderCurrent(commands) {
  // One command runs at a time; those received after it wait in lmp_node's queue.
  const open = commands.filter((c) => !c.outcome);
  const running = open.find((c) => c.stage !== 'received') || open[0];
  const queued = open.filter((c) => c !== running);
  $('queued').hidden = queued.length === 0;
  $('queued').textContent = 'Waiting: ' + queued.map((c) => c.command).join(' · ');
  $('current').hidden = !running;
  if (!running) return;
  $('current').dataset.commandId = running.id;
  $('current-command').textContent = running.command;
  const stage = $('current-stage');
  stage.textContent = running.stage.replace('_', ' ');
  stage.className = 'pill ' + running.stage;
  $('current-message').textContent = running.message;
  $('current-code').textContent = running.code;
  const awaiting = running.stage === 'awaiting_approval';
  $('approval').hidden = !awaiting;
  if (awaiting) renderPlan($('plan'), running.plan);
  renderTwin(awaiting ? running : null);
  $('current-said').replaceChildren(...running.said.map((line) => element('li', line)));
}

function renderHistory(commands) {
  const entries = [...commands].reverse().filter((c) => c.outcome).map((c) => {
    const item = element('li', null, 'history-entry');
    item.dataset.commandId = c.id;
    item.dataset.outcome = c.outcome;
    const title = element('div');
    title.append(element('span', c.outcome, 'pill ' + c.outcome), ' ', element('strong', c.command, 'command'));
    item.append(title, element('div', c.message, 'message'));
    if (c.said.length) item.append(element('ul', null, 'said'));
    for (const line of c.said) item.querySelector('ul.said').append(element('li', line));
    if (c.code) {
      const details = element('details');
      details.append(element('summary', 'code'), element('pre', c.code, 'code'));
      item.append(details);
    }
    return item;
  });
  $('history').replaceChildren(...entries);
}

function renderNotices(notices) {
  $('notices').replaceChildren(...notices.slice(-4).map((n) => element('li', n.text, n.level)));
}

function render(state) {
  $('graph-state').textContent = (state.namespace ? state.namespace + ': ' : '') + state.graph;
  renderCameras(state.streams);
  renderCurrent(state.commands);
  renderHistory(state.commands);
  renderNotices(state.notices);
}

function connect() {
  socket = new WebSocket(`ws://${location.host}/api/events`);
  socket.addEventListener('open', () => { $('connection').textContent = 'connected'; });
  socket.addEventListener('message', (event) => {
    const message = JSON.parse(event.data);
    if (message.type === 'state') render(message.state);
    else if (message.type === 'reply') $('notices').append(element('li', message.text, 'error'));
  });
  socket.addEventListener('close', () => {
    $('connection').textContent = 'disconnected: retrying';
    setTimeout(connect, 1000);
  });
}

document.addEventListener('DOMContentLoaded', () => {
  $('command-form').addEventListener('submit', (event) => {
    event.preventDefault();
    const text = $('command-input').value.trim();
    if (!text) return;
    send({ op: 'run', command: text });
    $('command-input').value = '';
  });
  $('stop-button').addEventListener('click', () => send({ op: 'stop' }));
  $('reset-button').addEventListener('click', () => send({ op: 'reset' }));
  const decide = (op) => () => {
    const id = $('current').dataset.commandId;
    if (id) send({ op, command_id: id });
  };
  $('approve-button').addEventListener('click', decide('approve'));
  $('reject-button').addEventListener('click', decide('reject'));
  connect();
});
