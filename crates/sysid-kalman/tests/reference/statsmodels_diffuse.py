"""Reference values for tests/statsmodels_diffuse.rs, made with statsmodels 0.15.0 and
numpy 2.4.6 (run: python statsmodels_diffuse.py): the exact diffuse initialisation
(`Initialization(k, "diffuse")`, Durbin and Koopman ch. 5, univariate treatment).
Prints the values pinned in the test."""
from statsmodels.tsa.statespace.initialization import Initialization
np.set_printoptions(precision=17)
def run(A,C,Q,R,y,init, B=None,u=None):
    p,T=y.shape; n=A.shape[0]
    mod=sm.tsa.statespace.MLEModel(y.T,k_states=n)
    mod['design']=C; mod['transition']=A; mod['selection']=np.eye(n)
    mod['state_cov']=Q; mod['obs_cov']=R
    if B is not None: mod['state_intercept']=B@u
    mod.ssm.initialization=init
    res=mod.ssm.smooth()
    return res
t=np.arange(1,61)
# (a) local level, all diffuse
y=(10+np.cumsum(np.sin(0.7*t))+0.5*np.cos(1.9*t))[None,:].copy(); y[0,[4,5,30]]=np.nan
r=run(np.eye(1),np.eye(1),np.array([[0.8]]),np.array([[1.5]]),y,Initialization(1,'diffuse'))
print('a llf',repr(float(r.llf)),'nobs_diffuse',r.nobs_diffuse)
for k in [0,4,59]: print(' a',k,repr(r.smoothed_state[0,k]),repr(r.smoothed_state_cov[0,0,k]))
for k in [0,1,2,59]: print(' a filt',k,repr(r.filtered_state[0,k]),repr(r.filtered_state_cov[0,0,k]))
# (b) local linear trend 2 diffuse, missing, 
A=np.array([[1.0,1.0],[0.0,1.0]]); C=np.array([[1.0,0.0]])
y=(0.05*t**1.5+np.sin(0.4*t))[None,:].copy(); y[0,[0,10,11,40]]=np.nan
r=run(A,C,np.diag([0.3,0.01]),np.array([[0.7]]),y,Initialization(2,'diffuse'))
print('b llf',repr(float(r.llf)),'nobs_diffuse',r.nobs_diffuse)
for k in [0,1,30,59]: print(' b',k,repr(list(r.smoothed_state[:,k])),repr(list(r.smoothed_state_cov[:,:,k].ravel())))
# (c) mixed: level diffuse + AR(1) stationary
A=np.diag([1.0,0.7]); C=np.array([[1.0,1.0]])
y=(3+np.sin(0.3*t)+0.4*np.cos(2.3*t))[None,:].copy(); y[0,[20]]=np.nan
init=Initialization(2); init.set(0,'diffuse'); init.set(1,'stationary')
r=run(A,C,np.diag([0.1,0.5]),np.array([[0.2]]),y,init)
print('c llf',repr(float(r.llf)),'nobs_diffuse',r.nobs_diffuse, 'stat var', 0.5/(1-0.49))
for k in [0,59]: print(' c',k,repr(list(r.smoothed_state[:,k])),repr(list(r.smoothed_state_cov[:,:,k].ravel())))
# (d) two outputs, correlated R, partial missing, 2 states all diffuse, input
A=np.array([[0.9,0.3],[0.0,1.0]]); C=np.array([[1.0,0.0],[0.5,1.0]]); B=np.array([[1.0],[0.2]])
u=np.cos(0.5*t)[None,:]
y=np.vstack([np.sin(0.2*t)+0.4*np.cos(0.9*t), 0.5*np.cos(0.3*t)-0.2*np.sin(1.3*t)+0.02*t])
y[1,0]=np.nan; y[0,[5,6]]=np.nan; y[:,33]=np.nan
R=np.array([[0.2,0.05],[0.05,0.1]])
r=run(A,C,np.array([[0.5,0.1],[0.1,0.3]]),R,y,Initialization(2,'diffuse'),B=B,u=u)
print('d llf',repr(float(r.llf)),'nobs_diffuse',r.nobs_diffuse)
for k in [0,1,33,59]: print(' d',k,repr(list(r.smoothed_state[:,k])),repr(list(r.smoothed_state_cov[:,:,k].ravel())))
