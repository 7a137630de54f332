// Over 400 lines (≈ 820): the element kernels, the nodal-volume
// term, Newton with its line search and the reused-tangent step share one private Impl (the
// assembled pattern and the factor); split, they would each need that state exposed.
#include "physics/tissue/tissue_model.h"

#include "core/errors.h"

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>
#include <Eigen/CholmodSupport>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <set>
#include <string>

// OpenBLAS, when it is the system's BLAS, runs CHOLMOD's dense blocks on
// TissueModelOptions::solver_threads: beside the haptic loop and the display one (OpenBLAS's
// spinning threads took 22 s of system time in a 30 s indentation run of the linear model).
extern "C" void openblas_set_num_threads(int) __attribute__((weak));

namespace organsmith::physics {

namespace {

struct QuadPoint {
  std::array<double, 30> g;  ///< dN_a/dX, node-major (a*3 + j)
  double w = 0.0;            ///< weight × reference volume factor
};

// Shape-function gradients with respect to the natural coordinates (ξ, η, ζ) of a 4- or
// 10-node tetrahedron at one point; barycentric L1 = 1 − ξ − η − ζ, L2 = ξ, L3 = η, L4 = ζ.
void natural_gradients(int npe, const Eigen::Vector3d& xi, Eigen::Matrix<double, 10, 3>& dN) {
  dN.setZero();
  const double L[4] = {1 - xi.sum(), xi[0], xi[1], xi[2]};
  // dL_i/dξ_j
  const double dL[4][3] = {{-1, -1, -1}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  if (npe == 4) {
    for (int a = 0; a < 4; ++a)
      for (int j = 0; j < 3; ++j) dN(a, j) = dL[a][j];
    return;
  }
  for (int a = 0; a < 4; ++a)  // corners: L(2L − 1)
    for (int j = 0; j < 3; ++j) dN(a, j) = (4 * L[a] - 1) * dL[a][j];
  const int edge[6][2] = {{0, 1}, {1, 2}, {2, 0}, {0, 3}, {1, 3}, {2, 3}};
  for (int m = 0; m < 6; ++m) {  // mid-edge: 4 L_i L_j
    const int i = edge[m][0], k = edge[m][1];
    for (int j = 0; j < 3; ++j) dN(4 + m, j) = 4 * (dL[i][j] * L[k] + L[i] * dL[k][j]);
  }
}

}  // namespace

TissueMesh corner_mesh(const TissueMesh& q, std::vector<std::int32_t>* new_id) {
  if (q.nodes_per_element == 4) {
    if (new_id) {
      new_id->resize(q.nodes_mm.size());
      for (std::size_t i = 0; i < new_id->size(); ++i) (*new_id)[i] = std::int32_t(i);
    }
    return q;
  }
  std::vector<std::int32_t> id(q.nodes_mm.size(), -1);
  TissueMesh r;
  r.nodes_per_element = 4;
  r.laws = q.laws;
  r.law_of_element = q.law_of_element;
  for (const auto& e : q.elements) {
    std::array<std::int32_t, 10> c;
    c.fill(-1);
    for (int k = 0; k < 4; ++k) {
      if (id[e[k]] < 0) {
        id[e[k]] = std::int32_t(r.nodes_mm.size());
        r.nodes_mm.push_back(q.nodes_mm[e[k]]);
      }
      c[k] = id[e[k]];
    }
    r.elements.push_back(c);
  }
  if (new_id) *new_id = std::move(id);
  return r;
}

struct TissueModel::Impl {
  int npe = 4;
  std::vector<std::vector<QuadPoint>> qp;   ///< per element
  std::vector<double> mass;                  ///< lumped, per node (t)
  Eigen::SparseMatrix<double> K;             ///< full pattern, 3N × 3N

  std::vector<std::array<std::int32_t, 3>> block_cols;  ///< value index of rows 3a..3a+2 in columns 3b+k
  // CHOLMOD's supernodal Cholesky (SuiteSparse, with the system's BLAS): on the default
  // gallbladder's 10-node model (11 838 unknowns) 130 ms a factorisation against 770 ms for
  // Eigen's SimplicialLDLT. A tangent that is not positive definite (past a limit point) falls
  // back to LDLᵀ.
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>> llt;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt;
  bool analysed = false, use_ldlt = false;
  // The last factorisation: for which boundary and step, and the free rows' coupling to the held
  // set's translation (for reusing it).
  bool factor_valid = false;
  std::uint64_t factor_boundary = 0;
  double factor_dt = -1.0;
  Eigen::MatrixXd Kfh;
  bool factorize() {
    if (!analysed) {
      llt.cholmod().print = 0;  // a tangent past a limit point is handled below, not printed
      llt.analyzePattern(K);
      analysed = true;
    }
    use_ldlt = false;
    llt.factorize(K);
    if (llt.info() == Eigen::Success) return true;
    // Not positive definite (past a limit point, or a compressed nodal-volume patch): the
    // diagonal shifted until it is, so that the step stays a descent direction of the energy
    // (the line search needs one; the converged answer does not depend on the tangent).
    double dmean = 0.0;
    for (int d = 0; d < K.cols(); ++d) dmean += std::abs(K.coeff(d, d));
    dmean /= std::max<Eigen::Index>(1, K.cols());
    double added = 0.0;
    for (double tau : {1e-4, 1e-3, 1e-2, 1e-1, 1.0}) {
      for (int d = 0; d < K.cols(); ++d) K.coeffRef(d, d) += (tau - added) * dmean;
      added = tau;
      llt.factorize(K);
      if (llt.info() == Eigen::Success) return true;
    }
    use_ldlt = true;
    ldlt.compute(K);
    return ldlt.info() == Eigen::Success;
  }
  template <class Rhs>
  Eigen::MatrixXd solve(const Rhs& b) const {
    return use_ldlt ? Eigen::MatrixXd(ldlt.solve(b)) : Eigen::MatrixXd(llt.solve(b));
  }
  Eigen::VectorXd f;                         ///< internal force at the last evaluation
  std::vector<char> constrained;             ///< per DOF
  // Nodal volumetric energy (linear tetrahedra).
  bool nodal = false;
  std::vector<OgdenSolid> dev_laws;          ///< the laws without their volumetric term
  std::vector<double> Vn, Kn;                ///< per node: reference volume share, bulk modulus
  std::vector<std::int32_t> ne_start, ne_list;  ///< node → elements (CSR)
  std::vector<double> Ve;                    ///< per element reference volume

  bool evaluate(const TissueMesh& mesh, const Eigen::VectorXd& u, double& energy, Eigen::VectorXd& f,
                Eigen::SparseMatrix<double>* K) const;
  std::int32_t value_index(int row, int col) const {
    const int* inner = K.innerIndexPtr();
    const int* outer = K.outerIndexPtr();
    return std::int32_t(std::lower_bound(inner + outer[col], inner + outer[col + 1], row) - inner);
  }
};

TissueModel::TissueModel(TissueMesh mesh, TissueModelOptions options)
    : mesh_(std::move(mesh)), options_(options), impl_(std::make_unique<Impl>()) {
  if (openblas_set_num_threads) openblas_set_num_threads(std::max(1, options_.solver_threads));
  Impl& I = *impl_;
  const std::size_t n = mesh_.nodes_mm.size();
  const int npe = mesh_.nodes_per_element;
  if (n == 0 || mesh_.elements.empty()) throw InputError(ExitCode::unsupported_input, "the tissue model has no nodes or no elements");
  if (npe != 4 && npe != 10) throw InputError(ExitCode::unsupported_input, "tetrahedra need 4 or 10 nodes");
  if (mesh_.law_of_element.size() != mesh_.elements.size())
    throw InputError(ExitCode::unsupported_input, "the tissue model needs one law per element");
  I.npe = npe;
  I.mass.assign(n, 0.0);
  // Quadrature: one point (linear) or the four-point rule CalculiX uses for C3D10.
  std::vector<std::pair<Eigen::Vector3d, double>> rule;
  if (npe == 4) rule.push_back({Eigen::Vector3d(0.25, 0.25, 0.25), 1.0 / 6.0});
  else {
    const double a = 0.5854101966249685, b = 0.1381966011250105;
    for (const Eigen::Vector3d& p : {Eigen::Vector3d(b, b, b), Eigen::Vector3d(a, b, b), Eigen::Vector3d(b, a, b), Eigen::Vector3d(b, b, a)})
      rule.push_back({p, 1.0 / 24.0});
  }
  I.qp.resize(mesh_.elements.size());
  for (std::size_t e = 0; e < mesh_.elements.size(); ++e) {
    const auto& el = mesh_.elements[e];
    for (int a = 0; a < npe; ++a)
      if (el[a] < 0 || std::size_t(el[a]) >= n)
        throw InputError(ExitCode::unsupported_input, "element " + std::to_string(e + 1) + " names a node that does not exist");
    if (mesh_.law_of_element[e] < 0 || std::size_t(mesh_.law_of_element[e]) >= mesh_.laws.size())
      throw InputError(ExitCode::unsupported_input, "element " + std::to_string(e + 1) + " has no law");
    double vol = 0.0;
    for (const auto& [xi, w] : rule) {
      Eigen::Matrix<double, 10, 3> dN;
      natural_gradients(npe, xi, dN);
      Eigen::Matrix3d Jm = Eigen::Matrix3d::Zero();  // dX/dξ
      for (int a = 0; a < npe; ++a) Jm += mesh_.nodes_mm[el[a]] * dN.row(a);
      const double det = Jm.determinant();
      if (!(det > 0))
        throw InputError(ExitCode::unsupported_input, "element " + std::to_string(e + 1) + " has no positive volume");
      const Eigen::Matrix3d Jinv = Jm.inverse();
      QuadPoint q;
      q.g.fill(0.0);
      for (int a = 0; a < npe; ++a) {
        const Eigen::RowVector3d g = dN.row(a) * Jinv;
        for (int j = 0; j < 3; ++j) q.g[a * 3 + j] = g[j];
      }
      q.w = w * det;
      vol += q.w;
      I.qp[e].push_back(q);
    }
    for (int a = 0; a < npe; ++a) I.mass[el[a]] += density_t_per_mm3 * vol / npe;
    I.Ve.push_back(vol);
  }
  I.nodal = options.nodal_volume && npe == 4;
  I.dev_laws = mesh_.laws;
  if (I.nodal) {
    for (auto& l : I.dev_laws) l.bulk = 0.0;
    I.Vn.assign(n, 0.0);
    I.Kn.assign(n, 0.0);
    std::vector<std::int32_t> count(n + 1, 0);
    for (std::size_t e = 0; e < mesh_.elements.size(); ++e)
      for (int a = 0; a < 4; ++a) {
        const std::int32_t v = mesh_.elements[e][a];
        I.Vn[v] += I.Ve[e] / 4;
        I.Kn[v] += I.Ve[e] / 4 * mesh_.laws[mesh_.law_of_element[e]].bulk;
        ++count[v + 1];
      }
    for (std::size_t i = 0; i < n; ++i) {
      if (I.Vn[i] > 0) I.Kn[i] /= I.Vn[i];
      count[i + 1] += count[i];
    }
    I.ne_start = count;
    I.ne_list.assign(count[n], 0);
    std::vector<std::int32_t> fill(count.begin(), count.end() - 1);
    for (std::size_t e = 0; e < mesh_.elements.size(); ++e)
      for (int a = 0; a < 4; ++a) I.ne_list[fill[mesh_.elements[e][a]]++] = std::int32_t(e);
  }
  // Sparse pattern: node adjacency through elements, 3×3 dense blocks.
  std::vector<std::set<std::int32_t>> adj(n);
  for (const auto& el : mesh_.elements)
    for (int a = 0; a < npe; ++a)
      for (int b = 0; b < npe; ++b) adj[el[a]].insert(el[b]);
  if (I.nodal)  // a node's J couples every node of its elements with every other
    for (std::size_t v = 0; v < n; ++v) {
      std::vector<std::int32_t> patch;
      for (std::int32_t k = I.ne_start[v]; k < I.ne_start[v + 1]; ++k)
        for (int a = 0; a < 4; ++a) patch.push_back(mesh_.elements[I.ne_list[k]][a]);
      for (std::int32_t x : patch)
        for (std::int32_t y : patch) adj[x].insert(y);
    }
  std::vector<Eigen::Triplet<double>> t;
  for (std::size_t i = 0; i < n; ++i)
    for (std::int32_t j : adj[i])
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) t.emplace_back(int(3 * i + r), int(3 * j + c), 0.0);
  I.K.resize(int(3 * n), int(3 * n));
  I.K.setFromTriplets(t.begin(), t.end());
  I.K.makeCompressed();
  const int* outer = I.K.outerIndexPtr();
  const int* inner = I.K.innerIndexPtr();
  auto find = [&](int row, int col) {
    const int* b = inner + outer[col];
    const int* e = inner + outer[col + 1];
    return std::int32_t(std::lower_bound(b, e, row) - inner);
  };
  I.block_cols.reserve(mesh_.elements.size() * npe * npe);
  for (const auto& el : mesh_.elements)
    for (int a = 0; a < npe; ++a)
      for (int b = 0; b < npe; ++b)
        I.block_cols.push_back({find(3 * el[a], 3 * el[b]), find(3 * el[a], 3 * el[b] + 1), find(3 * el[a], 3 * el[b] + 2)});
  u_ = Eigen::VectorXd::Zero(3 * n);
  v_ = Eigen::VectorXd::Zero(3 * n);
  I.f = Eigen::VectorXd::Zero(3 * n);
  I.constrained.assign(3 * n, 0);
}

TissueModel::~TissueModel() = default;

void TissueModel::reset() {
  u_.setZero();
  v_.setZero();
  impl_->f.setZero();
  held_stiffness_.setZero();
  held_response_.resize(0, 0);
}

void TissueModel::set_displacement_mm(const Eigen::VectorXd& u) {
  if (u.size() != u_.size()) throw InputError(ExitCode::unsupported_input, "a displacement of the wrong size");
  u_ = u;
  v_.setZero();
}

void TissueModel::set_boundary(std::vector<std::int32_t> fixed, std::vector<std::int32_t> held) {
  const std::size_t n = node_count();
  for (auto* s : {&fixed, &held}) {
    std::sort(s->begin(), s->end());
    s->erase(std::unique(s->begin(), s->end()), s->end());
    for (std::int32_t i : *s)
      if (i < 0 || std::size_t(i) >= n) throw InputError(ExitCode::unsupported_input, "a boundary node does not exist");
  }
  std::vector<std::int32_t> h;
  std::set_difference(held.begin(), held.end(), fixed.begin(), fixed.end(), std::back_inserter(h));
  fixed_ = std::move(fixed);
  held_ = std::move(h);
  ++boundary_version_;
  held_response_.resize(0, 0);
  impl_->constrained.assign(3 * n, 0);
  for (auto* s : {&fixed_, &held_})
    for (std::int32_t i : *s)
      for (int k = 0; k < 3; ++k) impl_->constrained[3 * i + k] = 1;
}

namespace {

// Energy, internal force and (optionally) tangent of the whole mesh at displacement u. False
// when an element is inverted.
}  // namespace

bool TissueModel::Impl::evaluate(const TissueMesh& mesh, const Eigen::VectorXd& u, double& energy, Eigen::VectorXd& f,
                                 Eigen::SparseMatrix<double>* K) const {
  const auto& qps = qp;
  const int npe = mesh.nodes_per_element;
  energy = 0.0;
  f.setZero();
  double* kv = K ? K->valuePtr() : nullptr;
  if (K) std::fill(kv, kv + K->nonZeros(), 0.0);
  SolidPoint sp;
  Eigen::Matrix<double, 6, 30> B;
  Eigen::Matrix<double, 6, 30> DB;
  for (std::size_t e = 0; e < mesh.elements.size(); ++e) {
    const auto& el = mesh.elements[e];
    const OgdenSolid& law = dev_laws[mesh.law_of_element[e]];
    for (const QuadPoint& q : qps[e]) {
      Eigen::Matrix3d F = Eigen::Matrix3d::Identity();
      for (int a = 0; a < npe; ++a) {
        const Eigen::Vector3d ua = u.segment<3>(3 * el[a]);
        const Eigen::RowVector3d g(q.g[a * 3], q.g[a * 3 + 1], q.g[a * 3 + 2]);
        F += ua * g;
      }
      if (!evaluate_ogden(law, F, sp, K != nullptr)) return false;
      energy += q.w * sp.energy;
      const Eigen::Matrix3d P = F * sp.S;
      for (int a = 0; a < npe; ++a) {
        const Eigen::Vector3d g(q.g[a * 3], q.g[a * 3 + 1], q.g[a * 3 + 2]);
        f.segment<3>(3 * el[a]) += q.w * (P * g);
      }
      if (!K) continue;
      for (int a = 0; a < npe; ++a) {
        const double* g = &q.g[a * 3];
        for (int i = 0; i < 3; ++i) {
          const int c = 3 * a + i;
          B(0, c) = F(i, 0) * g[0];
          B(1, c) = F(i, 1) * g[1];
          B(2, c) = F(i, 2) * g[2];
          B(3, c) = F(i, 0) * g[1] + F(i, 1) * g[0];
          B(4, c) = F(i, 1) * g[2] + F(i, 2) * g[1];
          B(5, c) = F(i, 2) * g[0] + F(i, 0) * g[2];
        }
      }
      const int nd = 3 * npe;
      DB.leftCols(nd).noalias() = sp.D * B.leftCols(nd);
      const std::size_t base = e * std::size_t(npe * npe);
      for (int a = 0; a < npe; ++a) {
        const Eigen::Vector3d ga(q.g[a * 3], q.g[a * 3 + 1], q.g[a * 3 + 2]);
        const Eigen::Vector3d Sga = sp.S * ga;
        for (int b = 0; b < npe; ++b) {
          const Eigen::Vector3d gb(q.g[b * 3], q.g[b * 3 + 1], q.g[b * 3 + 2]);
          const double geo = Sga.dot(gb);
          const Eigen::Matrix3d k = B.middleCols<3>(3 * a).transpose() * DB.middleCols<3>(3 * b);
          const auto& cols = block_cols[base + std::size_t(a * npe + b)];
          for (int kc = 0; kc < 3; ++kc)
            for (int r = 0; r < 3; ++r) kv[cols[kc] + r] += q.w * (k(r, kc) + (r == kc ? geo : 0.0));
        }
      }
    }
  }
  if (!nodal) return true;
  // Nodal volumetric energy: v_e and ∂v_e/∂x_a = v_e h_a (h_a = F⁻ᵀ g_a, the spatial gradient),
  // J_n = Σ_{e∋n} v_e/4 / V_n, Π = Σ_n V_n K_n/2 (J_n − 1)².
  const std::size_t ne = mesh.elements.size(), nn = mesh.nodes_mm.size();
  std::vector<std::array<Eigen::Vector3d, 4>> dv(ne);
  std::vector<double> ve(ne);
  std::vector<double> Jn(nn, 0.0);
  for (std::size_t e = 0; e < ne; ++e) {
    const auto& el = mesh.elements[e];
    const QuadPoint& q = qps[e][0];
    Eigen::Matrix3d F = Eigen::Matrix3d::Identity();
    for (int a = 0; a < 4; ++a) F += u.segment<3>(3 * el[a]) * Eigen::RowVector3d(q.g[a * 3], q.g[a * 3 + 1], q.g[a * 3 + 2]);
    const double J = F.determinant();
    if (!(J > 0)) return false;
    ve[e] = J * Ve[e];
    const Eigen::Matrix3d FinvT = F.inverse().transpose();
    for (int a = 0; a < 4; ++a) dv[e][a] = ve[e] * (FinvT * Eigen::Vector3d(q.g[a * 3], q.g[a * 3 + 1], q.g[a * 3 + 2]));
    for (int a = 0; a < 4; ++a) Jn[el[a]] += ve[e] / 4;
  }
  std::vector<double> pn(nn, 0.0);
  for (std::size_t v = 0; v < nn; ++v) {
    if (!(Vn[v] > 0)) continue;
    Jn[v] /= Vn[v];
    energy += 0.5 * Vn[v] * Kn[v] * (Jn[v] - 1) * (Jn[v] - 1);
    pn[v] = Kn[v] * (Jn[v] - 1);
  }
  std::vector<double> pe(ne, 0.0);
  for (std::size_t e = 0; e < ne; ++e) {
    const auto& el = mesh.elements[e];
    pe[e] = 0.25 * (pn[el[0]] + pn[el[1]] + pn[el[2]] + pn[el[3]]);
    for (int a = 0; a < 4; ++a) f.segment<3>(3 * el[a]) += pe[e] * dv[e][a];
  }
  if (!K) return true;
  kv = K->valuePtr();
  // Σ_e p̄_e ∂²v_e/∂x_a∂x_b, with ∂²v/∂x_ai∂x_bk = v (h_ai h_bk − h_ak h_bi).
  for (std::size_t e = 0; e < ne; ++e) {
    const auto& el = mesh.elements[e];
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) {
        if (a == b) continue;
        const Eigen::Vector3d ha = dv[e][a] / ve[e], hb = dv[e][b] / ve[e];
        const Eigen::Matrix3d H = pe[e] * ve[e] * (ha * hb.transpose() - hb * ha.transpose());
        const auto& cols = block_cols[e * 16 + std::size_t(a * 4 + b)];
        for (int kc = 0; kc < 3; ++kc)
          for (int r = 0; r < 3; ++r) kv[cols[kc] + r] += H(r, kc);
      }
  }
  // Σ_n V_n K_n ∇J_n ∇J_nᵀ over each node's patch.
  std::vector<std::int32_t> pid;
  std::vector<Eigen::Vector3d> pg;
  for (std::size_t v = 0; v < nn; ++v) {
    if (!(Vn[v] > 0)) continue;
    pid.clear();
    pg.clear();
    for (std::int32_t k = ne_start[v]; k < ne_start[v + 1]; ++k) {
      const std::int32_t e = ne_list[k];
      for (int a = 0; a < 4; ++a) {
        const std::int32_t node = mesh.elements[e][a];
        const auto it = std::find(pid.begin(), pid.end(), node);
        const Eigen::Vector3d g = dv[e][a] / (4 * Vn[v]);
        if (it == pid.end()) pid.push_back(node), pg.push_back(g);
        else pg[std::size_t(it - pid.begin())] += g;
      }
    }
    const double c = Vn[v] * Kn[v];
    for (std::size_t x = 0; x < pid.size(); ++x)
      for (std::size_t y = 0; y < pid.size(); ++y) {
        const Eigen::Matrix3d B = c * pg[x] * pg[y].transpose();
        for (int kc = 0; kc < 3; ++kc) {
          const std::int32_t at = value_index(3 * pid[x], 3 * pid[y] + kc);
          for (int r = 0; r < 3; ++r) kv[at + r] += B(r, kc);
        }
      }
  }
  return true;
}

NewtonReport TissueModel::solve_static(const Eigen::Vector3d& held_mm, const NewtonOptions& options) {
  return newton(held_mm, 0.0, options);
}

NewtonReport TissueModel::step_dynamic(const Eigen::Vector3d& held_mm, double dt_s, const NewtonOptions& options) {
  return newton(held_mm, dt_s, options);
}

NewtonReport TissueModel::newton(const Eigen::Vector3d& held_mm, double dt, const NewtonOptions& o) {
  Impl& I = *impl_;
  const std::size_t n = node_count();
  const Eigen::VectorXd u0 = u_, v0 = v_;
  // Inertia (backward Euler): c_m M (u − u0) − M v0 / dt with c_m = 1/dt² + damping/dt.
  const double cm = dt > 0 ? 1.0 / (dt * dt) + damping_per_s / dt : 0.0;
  Eigen::VectorXd target = u_;
  for (std::int32_t i : fixed_) target.segment<3>(3 * i).setZero();
  for (std::int32_t i : held_) target.segment<3>(3 * i) = held_mm;
  auto potential = [&](const Eigen::VectorXd& u, double& phi, Eigen::VectorXd& r, Eigen::SparseMatrix<double>* K) {
    if (!I.evaluate(mesh_, u, phi, r, K)) return false;
    if (dt > 0)
      for (std::size_t i = 0; i < n; ++i) {
        const double m = I.mass[i];
        for (int k = 0; k < 3; ++k) {
          const std::size_t d = 3 * i + k;
          const double du = u[d] - u0[d];
          phi += 0.5 * cm * m * du * du - m * v0[d] * du / dt;
          r[d] += cm * m * du - m * v0[d] / dt;
        }
      }
    return true;
  };
  NewtonReport rep;
  double phi = 0.0;
  Eigen::VectorXd r(3 * n), rt(3 * n), du(3 * n), trial(3 * n);
  if (!potential(u_, phi, r, &I.K)) {
    rep.residual_N = std::numeric_limits<double>::infinity();
    return rep;
  }
  for (rep.iterations = 0; rep.iterations < o.max_iterations; ++rep.iterations) {
    if (o.abandon && o.abandon()) return rep;
    // Prescribed increments of the constrained DOFs, eliminated into the right-hand side.
    Eigen::VectorXd dc = Eigen::VectorXd::Zero(3 * n);
    double cgap = 0.0;
    for (std::size_t d = 0; d < 3 * n; ++d)
      if (I.constrained[d]) {
        dc[d] = target[d] - u_[d];
        cgap = std::max(cgap, std::abs(dc[d]));
      }
    if (dt > 0)
      for (std::size_t i = 0; i < n; ++i)
        for (int k = 0; k < 3; ++k) {
          const int d = int(3 * i + k);
          I.K.coeffRef(d, d) += cm * I.mass[i];
        }
    Eigen::VectorXd rhs = -r;
    double* kv = I.K.valuePtr();
    const int* outer = I.K.outerIndexPtr();
    const int* inner = I.K.innerIndexPtr();
    for (int col = 0; col < I.K.cols(); ++col)
      for (int p = outer[col]; p < outer[col + 1]; ++p) {
        const int row = inner[p];
        if (I.constrained[col] && !I.constrained[row]) rhs[row] -= kv[p] * dc[col];
      }
    // held-set Schur complement needs K_fc before it is zeroed: keep the coupling columns.
    Eigen::Matrix<double, Eigen::Dynamic, 3> Kfh = Eigen::Matrix<double, Eigen::Dynamic, 3>::Zero(3 * n, 3);
    Eigen::Matrix3d Khh = Eigen::Matrix3d::Zero();
    std::vector<char> held_dof(3 * n, 0);
    for (std::int32_t i : held_)
      for (int k = 0; k < 3; ++k) held_dof[3 * i + k] = 1;
    for (int col = 0; col < I.K.cols(); ++col) {
      if (!held_dof[col]) continue;
      for (int p = outer[col]; p < outer[col + 1]; ++p) {
        const int row = inner[p];
        if (!I.constrained[row]) Kfh(row, col % 3) += kv[p];
        else if (held_dof[row]) Khh(row % 3, col % 3) += kv[p];
      }
    }
    for (int col = 0; col < I.K.cols(); ++col)
      for (int p = outer[col]; p < outer[col + 1]; ++p) {
        const int row = inner[p];
        if (I.constrained[col] || I.constrained[row]) kv[p] = row == col ? 1.0 : 0.0;
      }
    for (std::size_t d = 0; d < 3 * n; ++d)
      if (I.constrained[d]) rhs[d] = dc[d];
    double rmax = 0.0;
    for (std::size_t d = 0; d < 3 * n; ++d)
      if (!I.constrained[d]) rmax = std::max(rmax, std::abs(r[d]));
    rep.residual_N = rmax;
    Eigen::Vector3d fh = Eigen::Vector3d::Zero();
    for (std::int32_t i : held_) fh += r.segment<3>(3 * i);
    const double tol = std::max(o.force_tolerance_N, o.relative_tolerance * fh.norm());
    if (!I.factorize()) break;
    I.factor_valid = true;
    I.factor_boundary = boundary_version_;
    I.factor_dt = dt;
    I.Kfh = Kfh;
    if (!held_.empty()) {
      const Eigen::MatrixXd X = I.solve(Eigen::MatrixXd(Kfh));
      held_stiffness_ = Khh - Kfh.transpose() * X;
      held_response_ = -X;
      for (std::int32_t i : held_)
        for (int k = 0; k < 3; ++k) held_response_.row(3 * i + k) = Eigen::RowVector3d::Unit(k);
    }
    if (rmax <= tol && cgap <= 1e-12) {
      rep.converged = true;
      break;
    }
    du = I.solve(rhs);
    // Backtracking on the potential: halve while an element inverts or the potential rises by
    // more than the step's first-order change says it may.
    const double slope = r.dot(du);
    double alpha = 1.0, phit = 0.0;
    bool ok = false;
    for (int ls = 0; ls < 12; ++ls, alpha *= 0.5) {
      trial = u_ + alpha * du;
      if (!potential(trial, phit, rt, &I.K)) continue;
      // Armijo on a descent direction. A step that moves prescribed nodes is taken even where it
      // stores energy (the press does work); one that moves none and is not a descent direction
      // (a tangent past a limit point) must at least not raise the potential.
      const bool prescribed = cgap > 1e-12;
      if (slope < 0 ? phit <= phi + 1e-4 * alpha * slope || ls == 11 : prescribed || phit <= phi + 1e-12 * (std::abs(phi) + 1.0)) {
        ok = true;
        break;
      }
    }
    if (!ok) break;
    u_ = trial;
    phi = phit;
    r = rt;
  }
  I.f = r;
  if (!rep.converged && rep.iterations > 0) {
    // The residual where the iterations left the state (the loop measured it before its step).
    double rmax = 0.0;
    for (std::size_t d = 0; d < 3 * n; ++d)
      if (!I.constrained[d]) rmax = std::max(rmax, std::abs(r[d]));
    rep.residual_N = rmax;
  }
  if (dt > 0) v_ = (u_ - u0) / dt;
  if (!rep.converged && !std::isfinite(rep.residual_N)) {
    u_ = u0;
    v_ = v0;
  }
  return rep;
}

NewtonReport TissueModel::solve_static_quasi_newton(const Eigen::Vector3d& held_mm, const NewtonOptions& o) {
  Impl& I = *impl_;
  const std::size_t n = node_count(), nd = 3 * n;
  NewtonReport rep;
  NewtonOptions one = o;
  one.max_iterations = 1;
  auto free_part = [&](Eigen::VectorXd& v) {
    for (std::size_t d = 0; d < nd; ++d)
      if (I.constrained[d]) v[d] = 0.0;
  };
  Eigen::VectorXd r(nd), g(nd), g_prev, u_prev, dir(nd), q(nd), rhs(nd);
  double phi = 0.0;
  for (int round = 0; round < 3; ++round) {
    if (o.abandon && o.abandon()) return rep;
    if (!I.factor_valid || I.factor_boundary != boundary_version_ || I.factor_dt != 0.0 || round > 0) {
      const NewtonReport full = newton(held_mm, 0.0, one);  // factorises, moves the held set
      rep.refreshed = true;
      rep.iterations += full.iterations;
      rep.residual_N = full.residual_N;
      if (full.converged || !u_.allFinite() || !std::isfinite(full.residual_N)) {
        rep.converged = full.converged;
        return rep;
      }
    }
    // Pairs (s, y) of this round: steps of the free nodes and the change of their residual.
    std::vector<Eigen::VectorXd> S, Y;
    std::vector<double> rho;
    constexpr std::size_t kPairs = 12;
    bool first = true;
    for (int it = 0; it < o.max_iterations; ++it) {
      if (o.abandon && o.abandon()) return rep;
      if (!I.evaluate(mesh_, u_, phi, r, nullptr)) break;  // an element inverted: refactorise from the last state
      I.f = r;
      g = r;
      free_part(g);
      const double rmax = g.cwiseAbs().maxCoeff();
      Eigen::Vector3d fh = Eigen::Vector3d::Zero();
      for (std::int32_t i : held_) fh += r.segment<3>(3 * i);
      double cgap = 0.0;
      for (std::int32_t i : held_) cgap = std::max(cgap, (held_mm - u_.segment<3>(3 * i)).cwiseAbs().maxCoeff());
      rep.residual_N = rmax;
      if (rmax <= std::max(o.force_tolerance_N, o.relative_tolerance * fh.norm()) && cgap <= 1e-12) {
        rep.converged = true;
        return rep;
      }
      if (!first) {
        Eigen::VectorXd s_k = u_ - u_prev;
        free_part(s_k);  // the held set's prescribed move is not a step of the energy's variables
        const Eigen::VectorXd y_k = g - g_prev;
        const double sy = s_k.dot(y_k);
        if (sy > 1e-12 * s_k.norm() * y_k.norm()) {
          if (S.size() == kPairs) S.erase(S.begin()), Y.erase(Y.begin()), rho.erase(rho.begin());
          S.push_back(s_k), Y.push_back(y_k), rho.push_back(1.0 / sy);
        }
      }
      if (first && cgap > 1e-12) {
        // The held set to its place, the free nodes by the tangent's response (a correction).
        Eigen::Vector3d shift = Eigen::Vector3d::Zero();
        rhs = -g;
        for (std::int32_t i : held_) {
          rhs.segment<3>(3 * i) = held_mm - u_.segment<3>(3 * i);
          shift += rhs.segment<3>(3 * i) / double(held_.size());
        }
        const Eigen::VectorXd c = I.Kfh * shift;
        for (std::size_t d = 0; d < nd; ++d)
          if (!I.constrained[d]) rhs[d] -= c[d];
        dir = I.solve(rhs);
        u_prev = u_, g_prev = g;
        u_ += dir;
        first = false;
        ++rep.iterations;
        continue;
      }
      // Two-loop recursion: dir = −H g, H the inverse tangent updated by the pairs.
      q = g;
      std::vector<double> a(S.size());
      for (std::size_t k = S.size(); k-- > 0;) {
        a[k] = rho[k] * S[k].dot(q);
        q -= a[k] * Y[k];
      }
      dir = I.solve(q);
      free_part(dir);
      for (std::size_t k = 0; k < S.size(); ++k) {
        const double b = rho[k] * Y[k].dot(dir);
        dir += (a[k] - b) * S[k];
      }
      dir = -dir;
      const double slope = g.dot(dir);
      if (!(slope < 0)) break;  // not a descent direction: refactorise
      // Backtracking on the energy (Armijo), or on the residual where the energy's change is
      // below its rounding (near equilibrium); an inverted element halves the step.
      u_prev = u_, g_prev = g;
      double alpha = 1.0, phit = 0.0;
      bool ok = false;
      for (int ls = 0; ls < 8 && !ok; ++ls, alpha *= 0.5) {
        u_ = u_prev + alpha * dir;
        if (!I.evaluate(mesh_, u_, phit, r, nullptr)) continue;
        double rt = 0.0;
        for (std::size_t d = 0; d < nd; ++d)
          if (!I.constrained[d]) rt = std::max(rt, std::abs(r[d]));
        ok = phit <= phi + 1e-4 * alpha * slope || (std::abs(alpha * slope) < 1e-10 * std::abs(phi) && rt < rmax);
      }
      if (!ok) {
        u_ = u_prev;
        break;
      }
      first = false;
      ++rep.iterations;
    }
  }
  return rep;
}

Eigen::Vector3d TissueModel::held_force_N() const {
  Eigen::Vector3d s = Eigen::Vector3d::Zero();
  for (std::int32_t i : held_) s += impl_->f.segment<3>(3 * i);
  return s;
}

double TissueModel::strain_energy_mJ() const {
  double W = 0.0;
  Eigen::VectorXd f(u_.size());
  impl_->evaluate(mesh_, u_, W, f, nullptr);
  return W;
}

namespace {
Eigen::Matrix3d mean_gradient(const TissueMesh& m, const std::vector<QuadPoint>& qps, const Eigen::VectorXd& u,
                              const std::array<std::int32_t, 10>& el) {
  Eigen::Matrix3d F = Eigen::Matrix3d::Zero();
  double w = 0.0;
  for (const QuadPoint& q : qps) {
    Eigen::Matrix3d Fq = Eigen::Matrix3d::Identity();
    for (int a = 0; a < m.nodes_per_element; ++a)
      Fq += u.segment<3>(3 * el[a]) * Eigen::RowVector3d(q.g[a * 3], q.g[a * 3 + 1], q.g[a * 3 + 2]);
    F += q.w * Fq;
    w += q.w;
  }
  return F / w;
}
}  // namespace

std::vector<double> TissueModel::element_max_stretch() const {
  std::vector<double> s(element_count());
  for (std::size_t e = 0; e < s.size(); ++e) {
    const Eigen::Matrix3d F = mean_gradient(mesh_, impl_->qp[e], u_, mesh_.elements[e]);
    s[e] = std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(F.transpose() * F, Eigen::EigenvaluesOnly).eigenvalues().maxCoeff());
  }
  return s;
}

std::vector<double> TissueModel::element_von_mises() const {
  std::vector<double> s(element_count(), 0.0);
  SolidPoint sp;
  for (std::size_t e = 0; e < s.size(); ++e) {
    const Eigen::Matrix3d F = mean_gradient(mesh_, impl_->qp[e], u_, mesh_.elements[e]);
    if (!evaluate_ogden(mesh_.laws[mesh_.law_of_element[e]], F, sp, false)) continue;
    const Eigen::Matrix3d sig = F * sp.S * F.transpose() / F.determinant();
    const Eigen::Matrix3d dev = sig - sig.trace() / 3.0 * Eigen::Matrix3d::Identity();
    s[e] = std::sqrt(1.5 * dev.squaredNorm());
  }
  return s;
}

}  // namespace organsmith::physics
