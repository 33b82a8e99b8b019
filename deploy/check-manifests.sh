#!/usr/bin/env bash
# Offline checks of the deployment files (docs/DEPLOY-CLUSTER.md), with only what
# deploy/install-deps.sh installs (node + deploy/k8s-check's npm packages, Debian's
# docker-compose); no cluster, no container runtime, no network.
#   deploy/check-manifests.sh [PROGRAM_DIR...]   the manifests as they are: 0 when valid
#   deploy/check-manifests.sh --self-test [PROGRAM_DIR...]   broken copies must be refused
# PROGRAM_DIR: folders with the built irradcast-server / irradcast-gateway, whose --help the
# options in the manifests are checked against.
# 1. deploy/k8s/*.yaml: the Kubernetes JSON schema of every object (kubernetes-models + ajv),
#    unknown fields refused (strict), and the references between them
#    (deploy/k8s-check/validate.mjs).
# 2. deploy/compose.yaml: `docker-compose config -q` (the Compose file schema; no daemon needed),
#    and its irradcast commands' options against the programs' --help (validate.mjs --compose).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
check=$root/deploy/k8s-check
[ -d "$check/node_modules/kubernetes-models" ] || {
  echo "check-manifests: $check/node_modules is missing: run deploy/install-deps.sh" >&2
  exit 1
}
command -v docker-compose >/dev/null || {
  echo "check-manifests: docker-compose is missing: run deploy/install-deps.sh" >&2
  exit 1
}

k8s() { node "$check/validate.mjs" --compose "$tmp_compose" "$@"; }
compose() { docker-compose --project-directory "$root/deploy" -f "$1" config -q; }

tmp_compose=$root/deploy/compose.yaml
if [ "${1:-}" != "--self-test" ]; then
  k8s "$root/deploy/k8s" "$@"
  compose "$root/deploy/compose.yaml"
  echo "check-manifests: deploy/compose.yaml valid"
  exit 0
fi

# --self-test: each broken copy must be refused, with the expected message.
shift
programs=("$@")
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
tmp_compose=$tmp/compose.yaml
failed=0
# expect_refused NAME PATTERN FILE SED_SCRIPT
expect_refused() {
  local name=$1 pattern=$2 file=$3 script=$4 out
  rm -rf "$tmp/k8s" "$tmp/nats" && cp -r "$root/deploy/k8s" "$tmp/k8s" && cp -r "$root/deploy/nats" "$tmp/nats"
  cp "$root/deploy/compose.yaml" "$tmp/"
  sed -i -e "$script" "$tmp/$file"
  if cmp -s "$tmp/$file" "$root/deploy/$file"; then
    echo "self-test $name: the edit changed nothing" && failed=1 && return
  fi
  if [ "$file" = compose.yaml ] && [ "$pattern" != "has no option" ]; then
    out=$(compose "$tmp/compose.yaml" 2>&1) && { echo "self-test $name: accepted"; failed=1; return; }
  else
    out=$(k8s "$tmp/k8s" "${programs[@]}" 2>&1) && { echo "self-test $name: accepted"; failed=1; return; }
  fi
  if grep -q -- "$pattern" <<<"$out"; then
    echo "self-test $name: refused: $(grep -m1 -- "$pattern" <<<"$out")"
  else
    echo "self-test $name: refused, but without '$pattern':"$'\n'"$out"
    failed=1
  fi
}
expect_refused type "replicas must be integer" k8s/gateway.yaml 's/^  replicas: 2$/  replicas: two/'
expect_refused unknown-field "spec.replcas: unknown field" k8s/gateway.yaml 's/^  replicas: 2$/  replcas: 2/'
expect_refused nested-field "securityContext.readOnlyRootFilesytem: unknown field" k8s/origin.yaml 's/readOnlyRootFilesystem/readOnlyRootFilesytem/'
expect_refused inline-field "volumeClaimTemplates\[0\].spec.accesModes: unknown field" k8s/nats.yaml 's/accessModes/accesModes/'
expect_refused required "must have required property containers" k8s/origin.yaml 's/^      containers:$/      containerz:/'
expect_refused pdb "PodDisruptionBudget/irradcast-gateway: its selector matches no" k8s/gateway.yaml '/minAvailable: 1/{n;n;n;s/irradcast-gateway/irradcast-gw/}'
expect_refused kind "unknown apiVersion/kind" k8s/nats.yaml 's/^kind: StatefulSet$/kind: StatefulSett/'
expect_refused yaml "YAML" k8s/config.yaml 's/^  IRRADCAST_SCENE: cornell$/  IRRADCAST_SCENE: [cornell/'
expect_refused selector "Service/irradcast-gateway: its selector matches no" k8s/gateway.yaml '/type: LoadBalancer/{n;n;s/irradcast-gateway/irradcast-gatway/}'
expect_refused labels "matchLabels does not match the pod template" k8s/nats.yaml '/^  template:/{n;n;n;s/name: nats/name: natz/}'
if [ ${#programs[@]} -gt 0 ]; then
  expect_refused program "irradcast-gateway has no option --nat" k8s/gateway.yaml 's/--nats=/--nat=/'
  expect_refused compose-program "has no option" compose.yaml 's/- --metrics-port=9100/- --metrics-prt=9100/'
fi
expect_refused port "target port 'metric' is not a container port" k8s/origin.yaml 's/targetPort: metrics/targetPort: metric/'
expect_refused hpa "scaleTargetRef Deployment/irradcast-gw is not here" k8s/gateway.yaml '/scaleTargetRef:/,/name:/s/name: irradcast-gateway/name: irradcast-gw/'
expect_refused secret "no Secret 'irradcast-tlss'" k8s/gateway.yaml 's/secretName: irradcast-tls$/secretName: irradcast-tlss/'
expect_refused compose "Unsupported config option" compose.yaml 's/^    restart: unless-stopped$/    restart_policy: unless-stopped/'
expect_refused compose-type "invalid type" compose.yaml 's/interval: 5s/interval: [5]/'
[ $failed -eq 0 ] && echo "check-manifests: self-test passed"
exit $failed
