// Offline check of the Kubernetes manifests in a folder (deploy/k8s): every document of every
// *.yaml is validated against the Kubernetes API's JSON schema of its apiVersion and kind (the
// schemas kubernetes-models carries, compiled for ajv: types, required fields, enums, formats),
// then the references between the objects are checked (selectors against pod labels, Service
// target ports against container ports, HPA and PDB targets, StatefulSet governing Services,
// ConfigMaps and Secrets used by pods, kustomization resources), and the irradcast programs'
// options in the containers' args (and in the commands of a Compose file) against their --help
// when a folder of programs is given.
//   node deploy/k8s-check/validate.mjs [--compose FILE] deploy/k8s [PROGRAM_DIR...]
// The compiled schemas accept unknown fields; a strict pass (as `kubeconform -strict`) walks each
// object along the field lists of kubernetes-models' type declarations (*.d.ts, generated from
// the same OpenAPI document) and refuses a field they do not have, so `replcas: 2` is an error.
// Exit 0: valid; 1: the errors, one a line.
import { execFileSync } from "node:child_process";
import fs from "node:fs";
import path from "node:path";
import { parseAllDocuments } from "yaml";

const argv = process.argv.slice(2);
let composeFile = null;
if (argv[0] === "--compose") {
  composeFile = argv[1];
  argv.splice(0, 2);
}
const dir = argv[0];
const programDirs = argv.slice(1);
if (!dir) {
  console.error("usage: node validate.mjs MANIFEST_DIR [PROGRAM_DIR...]");
  process.exit(2);
}
const errors = [];
const objects = [];  // { file, index, obj }
const where = (o) => `${o.file}: ${o.obj.kind}/${o.obj.metadata?.name ?? "?"}`;

// apiVersion "apps/v1" -> kubernetes-models/apps/v1, "v1" -> kubernetes-models/v1.
async function modelOf(apiVersion, kind) {
  if (typeof apiVersion !== "string" || !/^([a-z0-9.-]+\/)?v[0-9a-z]+$/.test(apiVersion))
    return null;
  try {
    const mod = await import(`kubernetes-models/${apiVersion}`);
    return mod[kind] ?? null;
  } catch {
    return null;
  }
}

// --- strict fields: the interfaces of kubernetes-models' .d.ts files ---
const nodeModules = path.join(path.dirname(new URL(import.meta.url).pathname), "node_modules");
const declarations = new Map();  // .d.ts file -> { fields: Map(name -> type text), imports, file }
// The members of an interface body or an inline object type: "name"?: TYPE; at depth 0 (TYPE
// may hold braces, angle brackets and semicolons inside them).
function members(body) {
  const fields = new Map();
  let d = 0, member = "";
  for (const c of body) {
    if (c === "{" || c === "<") d++;
    if (c === "}" || c === ">") d--;
    if (c === ";" && d === 0) {
      const m = member.trim().match(/^"([^"]+)"\??:\s*([\s\S]+)$/);
      if (m) fields.set(m[1], m[2].trim());
      member = "";
    } else member += c;
  }
  return fields;
}
function declaration(file) {
  if (declarations.has(file)) return declarations.get(file);
  let result = null;
  if (fs.existsSync(file)) {
    const text = fs.readFileSync(file, "utf8").replace(/\/\*[\s\S]*?\*\//g, "");
    const start = text.indexOf("export interface ");
    if (start >= 0) {
      const imports = new Map();
      for (const m of text.matchAll(/import \{ ([^}]+) \} from "([^"]+)";/g))
        for (const name of m[1].split(",")) imports.set(name.trim(), m[2]);
      let depth = 0, i = text.indexOf("{", start);
      const from = i;
      for (; i < text.length; ++i) {  // the interface's body, nested braces and all
        if (text[i] === "{") depth++;
        if (text[i] === "}" && --depth === 0) break;
      }
      result = { fields: members(text.slice(from + 1, i)), imports, file };
    }
  }
  declarations.set(file, result);
  return result;
}
// The declaration a field's type names: an imported interface, or an inline object type; null
// for a primitive, a union or a map ({ [key: string]: ... }), whose keys are free.
function typeOf(type, decl) {
  if (type.startsWith("{")) {
    const inner = type.slice(1, type.lastIndexOf("}"));
    if (/^\s*\[key: string\]/.test(inner)) return null;
    return { fields: members(inner), imports: decl.imports, file: decl.file };
  }
  if (!/^\w+$/.test(type) || !decl.imports.has(type)) return null;
  const spec = decl.imports.get(type);
  return declaration(spec.startsWith(".") ? path.resolve(path.dirname(decl.file), spec + ".d.ts")
                                          : path.join(nodeModules, spec + ".d.ts"));
}
function strict(value, decl, at, out) {
  if (!decl || value === null || typeof value !== "object" || Array.isArray(value)) return;
  for (const [key, v] of Object.entries(value)) {
    const type = decl.fields.get(key);
    if (type === undefined) {
      out.push(`${at}.${key}: unknown field`);
      continue;
    }
    const element = type.match(/^Array<([\s\S]+)>$/);
    const inner = typeOf(element ? element[1].trim() : type, decl);
    if (element && Array.isArray(v)) v.forEach((x, n) => strict(x, inner, `${at}.${key}[${n}]`, out));
    else if (!element) strict(v, inner, `${at}.${key}`, out);
  }
}

const files = fs.readdirSync(dir).filter((f) => f.endsWith(".yaml") || f.endsWith(".yml")).sort();
if (files.length === 0) errors.push(`${dir}: no manifests`);
let kustomization = null;
for (const file of files) {
  const text = fs.readFileSync(path.join(dir, file), "utf8");
  const docs = parseAllDocuments(text, { prettyErrors: true });
  for (const [index, doc] of docs.entries()) {
    for (const e of doc.errors) errors.push(`${file}: YAML: ${e.message.split("\n")[0]}`);
    if (doc.errors.length) continue;
    const obj = doc.toJS();
    if (obj === null || obj === undefined) continue;  // an empty document
    if (file === "kustomization.yaml") {
      kustomization = obj;
      continue;
    }
    if (typeof obj !== "object" || Array.isArray(obj)) {
      errors.push(`${file}: document ${index + 1} is not a mapping`);
      continue;
    }
    const Model = await modelOf(obj.apiVersion, obj.kind);
    if (!Model) {
      errors.push(`${file}: document ${index + 1}: unknown apiVersion/kind ${obj.apiVersion}/${obj.kind}`);
      continue;
    }
    try {
      new Model(obj).validate();
    } catch (e) {
      errors.push(`${file}: ${obj.kind}/${obj.metadata?.name ?? "?"}: ${e.message.replace(/\n/g, "; ")}`);
      continue;
    }
    const unknown = [];
    const dts = path.join(nodeModules, "kubernetes-models", obj.apiVersion, `${obj.kind}.d.ts`);
    if (!declaration(dts)) errors.push(`${file}: ${obj.kind}: no type declaration ${dts}`);
    strict(obj, declaration(dts), "", unknown);
    if (unknown.length) {
      for (const u of unknown) errors.push(`${file}: ${obj.kind}/${obj.metadata?.name ?? "?"}: ${u.slice(1)}`);
      continue;
    }
    objects.push({ file, index, obj });
  }
}

// ConfigMaps made by a configMapGenerator of a kustomization this one includes as a resource
// folder (deploy/nats: nats.conf as nats-config), with their files checked to exist.
for (const r of kustomization?.resources ?? []) {
  const sub = path.join(dir, r, "kustomization.yaml");
  if (!fs.existsSync(sub)) continue;
  const k = parseAllDocuments(fs.readFileSync(sub, "utf8"))[0]?.toJS() ?? {};
  for (const g of k.configMapGenerator ?? []) {
    for (const f of g.files ?? []) {
      const file = String(f).split("=").pop();
      if (!fs.existsSync(path.join(dir, r, file)))
        errors.push(`${r}/kustomization.yaml: configMapGenerator ${g.name}: no file '${file}'`);
    }
    objects.push({ file: `${r}/kustomization.yaml`, index: 0, obj: { kind: "ConfigMap", metadata: { name: g.name } } });
  }
}

// --- references between the objects ---
const byKind = (kind) => objects.filter((o) => o.obj.kind === kind);
const named = (kind, name) => byKind(kind).find((o) => o.obj.metadata.name === name);
const seen = new Set();
for (const o of objects) {
  const key = `${o.obj.kind}/${o.obj.metadata.name}`;
  if (seen.has(key)) errors.push(`${where(o)}: defined twice`);
  seen.add(key);
}
const workloads = [...byKind("Deployment"), ...byKind("StatefulSet")];
const podLabels = (w) => w.obj.spec.template.metadata?.labels ?? {};
const matches = (selector, labels) =>
  Object.keys(selector ?? {}).length > 0 &&
  Object.entries(selector).every(([k, v]) => labels[k] === v);
const containers = (w) => w.obj.spec.template.spec.containers ?? [];
const portNames = (w) => new Set(containers(w).flatMap((c) => (c.ports ?? []).map((p) => p.name)));
const portNumbers = (w) => new Set(containers(w).flatMap((c) => (c.ports ?? []).map((p) => p.containerPort)));

for (const w of workloads) {
  if (!matches(w.obj.spec.selector.matchLabels, podLabels(w)))
    errors.push(`${where(w)}: spec.selector.matchLabels does not match the pod template's labels`);
  const names = portNames(w);
  for (const c of containers(w)) {
    for (const probe of ["startupProbe", "readinessProbe", "livenessProbe"]) {
      const port = c[probe]?.httpGet?.port ?? c[probe]?.tcpSocket?.port;
      if (typeof port === "string" && !names.has(port))
        errors.push(`${where(w)}: container ${c.name}: ${probe} names port '${port}', which no container declares`);
    }
    for (const from of c.envFrom ?? []) {
      if (from.configMapRef && !from.configMapRef.optional && !named("ConfigMap", from.configMapRef.name))
        errors.push(`${where(w)}: container ${c.name}: no ConfigMap '${from.configMapRef.name}'`);
      if (from.secretRef && !from.secretRef.optional && !named("Secret", from.secretRef.name))
        errors.push(`${where(w)}: container ${c.name}: no Secret '${from.secretRef.name}'`);
    }
    const volumes = new Set((w.obj.spec.template.spec.volumes ?? []).map((v) => v.name));
    const claims = new Set((w.obj.spec.volumeClaimTemplates ?? []).map((v) => v.metadata?.name));
    for (const m of c.volumeMounts ?? [])
      if (!volumes.has(m.name) && !claims.has(m.name))
        errors.push(`${where(w)}: container ${c.name}: mounts volume '${m.name}', which the pod does not have`);
  }
  for (const v of w.obj.spec.template.spec.volumes ?? []) {
    if (v.secret && !v.secret.optional && !named("Secret", v.secret.secretName))
      errors.push(`${where(w)}: volume ${v.name}: no Secret '${v.secret.secretName}'`);
    if (v.configMap && !v.configMap.optional && !named("ConfigMap", v.configMap.name))
      errors.push(`${where(w)}: volume ${v.name}: no ConfigMap '${v.configMap.name}'`);
  }
  if (w.obj.kind === "StatefulSet" && !named("Service", w.obj.spec.serviceName))
    errors.push(`${where(w)}: spec.serviceName '${w.obj.spec.serviceName}' is not a Service here`);
}
for (const s of byKind("Service")) {
  const targets = workloads.filter((w) => matches(s.obj.spec.selector, podLabels(w)));
  if (targets.length === 0) {
    errors.push(`${where(s)}: its selector matches no workload's pods`);
    continue;
  }
  for (const p of s.obj.spec.ports ?? []) {
    const t = p.targetPort ?? p.port;
    const ok = targets.some((w) => (typeof t === "string" ? portNames(w).has(t) : portNumbers(w).has(t)));
    if (!ok) errors.push(`${where(s)}: port ${p.name ?? p.port}: target port '${t}' is not a container port of its pods`);
  }
}
for (const h of byKind("HorizontalPodAutoscaler")) {
  const ref = h.obj.spec.scaleTargetRef;
  if (!named(ref.kind, ref.name)) errors.push(`${where(h)}: scaleTargetRef ${ref.kind}/${ref.name} is not here`);
  if (h.obj.spec.minReplicas > h.obj.spec.maxReplicas) errors.push(`${where(h)}: minReplicas > maxReplicas`);
}
for (const b of byKind("PodDisruptionBudget"))
  if (!workloads.some((w) => matches(b.obj.spec.selector?.matchLabels, podLabels(w))))
    errors.push(`${where(b)}: its selector matches no workload's pods`);
if (kustomization) {
  for (const r of kustomization.resources ?? [])
    if (!fs.existsSync(path.join(dir, r))) errors.push(`kustomization.yaml: resource '${r}' does not exist`);
}

// --- the programs' options: every --flag of a command line must be in the program's --help ---
const helps = new Map();
function checkCommand(args, what) {
  const program = args[0];
  if (typeof program !== "string" || !program.startsWith("irradcast-") || programDirs.length === 0)
    return;
  const exe = programDirs.map((d) => path.join(d, program)).find((p) => fs.existsSync(p));
  if (!exe) {
    console.log(`note: ${program} is not built here; its options in ${what} are not checked`);
    return;
  }
  if (!helps.has(exe)) helps.set(exe, execFileSync(exe, ["--help"], { encoding: "utf8" }));
  for (const a of args.slice(1)) {
    const flag = typeof a === "string" && a.startsWith("--") ? a.split("=")[0] : null;
    if (flag && !new RegExp(`(^|[\\s,])${flag.replace(/[-]/g, "\\-")}([\\s,=]|$)`, "m").test(helps.get(exe)))
      errors.push(`${what}: ${program} has no option ${flag}`);
  }
}
for (const w of workloads)
  for (const c of containers(w)) checkCommand([...(c.command ?? []), ...(c.args ?? [])], where(w));
if (composeFile) {
  const compose = parseAllDocuments(fs.readFileSync(composeFile, "utf8"), { merge: true })[0].toJS();
  for (const [name, service] of Object.entries(compose?.services ?? {}))
    if (Array.isArray(service.command))
      checkCommand(service.command, `${path.basename(composeFile)}: service ${name}`);
}

if (errors.length) {
  for (const e of errors) console.error(`k8s-check: ${e}`);
  process.exit(1);
}
console.log(`k8s-check: ${objects.length} objects in ${files.length} files valid (${dir})`);
